"""The package stays readable: no class in python/layerpilot is longer than 400 lines."""

from __future__ import annotations

import ast
from pathlib import Path

import layerpilot

MAX_CLASS_LINES = 400
PACKAGE = Path(layerpilot.__file__).resolve().parent


def class_lengths(source: str) -> dict[str, int]:
    """Every class (nested ones too) in ``source`` by name, with its length in lines from ``class`` to its end."""
    return {node.name: node.end_lineno - node.lineno + 1 for node in ast.walk(ast.parse(source))
            if isinstance(node, ast.ClassDef)}


def test_the_measure_counts_a_class_from_its_line_to_its_last():
    source = "x = 1\n\nclass A:\n    a = 1\n\n    def f(self):\n        return 2\n\nclass B:\n    pass\n"
    assert class_lengths(source) == {"A": 5, "B": 2}


def test_no_class_is_longer_than_400_lines():
    files = sorted(PACKAGE.rglob("*.py"))
    assert len(files) > 50, f"expected the package's modules under {PACKAGE}, found {len(files)}"
    too_long = {f"{path.relative_to(PACKAGE)}:{name}": lines for path in files
                for name, lines in class_lengths(path.read_text()).items() if lines > MAX_CLASS_LINES}
    assert not too_long, f"classes over {MAX_CLASS_LINES} lines (split them by responsibility): {too_long}"
