"""The layering of pyproject.toml's import-linter contracts holds, and breaking it is caught.

`make test` runs `lint-imports` before pytest; this runs it too, so that a plain pytest run
checks the layers as well.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import importlinter
import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "python" / "layerpilot"

# Top to bottom; a package may import only the rows below its own.
ROWS = [{"cli"}, {"bench"}, {"eval"}, {"viz"}, {"nodes"}, {"missionfile"}, {"ros2"}, {"bus", "sim"}, {"mission"}, {"photos"},
        {"decide", "depth"}, {"layers", "link"}, {"map"}, {"camera"},
        {"grid", "config", "progress", "geometry", "geodesy"}]


def _contracts() -> dict[str, dict]:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    assert config["root_package"] == "layerpilot"
    return {c["id"]: c for c in config["contracts"]}


def _lint(package_parent: Path, *, isolated: bool) -> subprocess.CompletedProcess:
    """``lint-imports`` on pyproject.toml's contracts, for the layerpilot found under ``package_parent``."""
    env = dict(os.environ)
    command = [str(Path(sys.executable).parent / "lint-imports"), "--no-cache", "--no-logo",
               str(ROOT / "pyproject.toml")]
    if isolated:  # -S: no site (so not the editable install's module map), just the copy and import-linter
        site = Path(importlinter.__file__).resolve().parents[1]
        env["PYTHONPATH"] = os.pathsep.join([str(package_parent), str(site)])
        command = [sys.executable, "-S", "-c", "import sys; from importlinter.cli import lint_imports_command; "
                   "sys.argv[0] = 'lint-imports'; sys.exit(lint_imports_command())", *command[1:]]
    return subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)


def test_lint_imports_keeps_every_contract() -> None:
    done = _lint(ROOT / "python", isolated=False)
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"Contracts: {len(_contracts())} kept, 0 broken." in done.stdout


def test_the_contract_names_every_package_in_its_row() -> None:
    layers = _contracts()["layers"]
    assert layers["type"] == "layers" and layers["containers"] == ["layerpilot"] and layers["exhaustive"]
    rows = [{name.strip().strip("()") for name in row.split("|")} for row in layers["layers"]]
    assert rows == ROWS
    assert all("|" in row for row, names in zip(layers["layers"], rows) if len(names) > 1)  # independent siblings
    present = {p.stem for p in PACKAGE.glob("*.py") if p.stem != "__init__"} | {
        p.parent.name for p in PACKAGE.glob("*/__init__.py")}
    assert present <= set().union(*ROWS), f"not in any layer: {present - set().union(*ROWS)}"
    cycles = _contracts()["no-cycles"]
    assert cycles["type"] == "acyclic_siblings" and cycles["ancestors"] == ["layerpilot"]


def test_the_isolated_check_sees_the_same_package() -> None:
    """The check below runs without the editable install (on a copy); on the real tree it keeps too."""
    done = _lint(ROOT / "python", isolated=True)
    assert done.returncode == 0, done.stdout + done.stderr


@pytest.mark.parametrize("module, line, message", [
    ("layers/registry.py", "import layerpilot.decide", "layerpilot.layers is not allowed to import layerpilot.decide"),
    ("map/columns.py", "import layerpilot.bus", "layerpilot.map is not allowed to import layerpilot.bus"),
    ("sim/world.py", "import layerpilot.nodes", "layerpilot.sim is not allowed to import layerpilot.nodes"),
    ("link/frames.py", "import layerpilot.sim", "layerpilot.link is not allowed to import layerpilot.sim"),
    ("depth/__init__.py", "import layerpilot.decide", "layerpilot.depth is not allowed to import layerpilot.decide"),
    ("cli/nodes.py", "import layerpilot.cli.link", "No cycles are allowed in layerpilot.cli."),
])
def test_an_import_against_the_layers_breaks_the_check(tmp_path: Path, module: str, line: str, message: str) -> None:
    copy = tmp_path / "layerpilot"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    with open(copy / module, "a") as f:
        f.write(f"\n{line}  # the import under test\n")
    done = _lint(tmp_path, isolated=True)
    assert done.returncode == 1, done.stdout + done.stderr
    assert message in done.stdout and "BROKEN" in done.stdout, done.stdout
