"""Run reports: one self-contained HTML file (images inline), the same as Markdown, and JSON metrics."""

from __future__ import annotations

import base64
import html
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence


def format_value(value: Any) -> str:
    """Table cell text: floats to 4 significant digits, NaN as an en dash."""
    if isinstance(value, float):
        return "–" if math.isnan(value) else f"{value:.4g}"
    return str(value)


@dataclass
class _Table:
    headers: list[str]
    rows: list[list[Any]]


@dataclass
class _Image:
    path: Path
    caption: str


@dataclass
class Report:
    """A report built section by section, then written as report.html, report.md and metrics.json."""

    title: str
    _blocks: list[tuple[str, Any]] = field(default_factory=list)

    def heading(self, text: str) -> None:
        self._blocks.append(("heading", text))

    def text(self, text: str) -> None:
        self._blocks.append(("text", text))

    def table(self, headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> None:
        if any(len(r) != len(headers) for r in rows):
            raise ValueError(f"rows: every row needs {len(headers)} cells")
        self._blocks.append(("table", _Table(list(headers), [list(r) for r in rows])))

    def image(self, path: str | os.PathLike, caption: str = "") -> None:
        """A PNG in the run directory (HTML inlines it; Markdown links it relatively)."""
        path = Path(path)
        if path.suffix.lower() != ".png" or not path.is_file():
            raise ValueError(f"path: expected an existing .png file, got {path}")
        self._blocks.append(("image", _Image(path, caption)))

    def write(self, out_dir: str | os.PathLike, metrics: dict[str, Any]) -> dict[str, Path]:
        """Write the three files into ``out_dir``; returns their paths by kind."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths = {"html": out / "report.html", "md": out / "report.md", "json": out / "metrics.json"}
        paths["html"].write_text(self._html())
        paths["md"].write_text(self._markdown(out))
        paths["json"].write_text(json.dumps(_json_safe(metrics), indent=2, sort_keys=True) + "\n")
        return paths

    def _html(self) -> str:
        esc = html.escape
        parts = [
            "<!DOCTYPE html>",
            '<html><head><meta charset="utf-8">',
            f"<title>{esc(self.title)}</title>",
            "<style>body{font-family:sans-serif;max-width:1000px;margin:auto;padding:1em}"
            "table{border-collapse:collapse}td,th{border:1px solid #999;padding:4px 8px;text-align:right}"
            "th{background:#eee}img{max-width:100%}figure{display:inline-block;margin:0.5em}</style>",
            "</head><body>",
            f"<h1>{esc(self.title)}</h1>",
        ]
        for kind, block in self._blocks:
            if kind == "heading":
                parts.append(f"<h2>{esc(block)}</h2>")
            elif kind == "text":
                parts.append(f"<p>{esc(block)}</p>")
            elif kind == "table":
                head = "".join(f"<th>{esc(h)}</th>" for h in block.headers)
                body = "".join(
                    "<tr>" + "".join(f"<td>{esc(format_value(v))}</td>" for v in row) + "</tr>" for row in block.rows
                )
                parts.append(f"<table><tr>{head}</tr>{body}</table>")
            else:
                data = base64.b64encode(block.path.read_bytes()).decode("ascii")
                parts.append(
                    f'<figure><img alt="{esc(block.caption)}" src="data:image/png;base64,{data}">'
                    f"<figcaption>{esc(block.caption)}</figcaption></figure>"
                )
        parts.append("</body></html>")
        return "\n".join(parts) + "\n"

    def _markdown(self, out: Path) -> str:
        lines = [f"# {self.title}", ""]
        for kind, block in self._blocks:
            if kind == "heading":
                lines += [f"## {block}", ""]
            elif kind == "text":
                lines += [block, ""]
            elif kind == "table":
                lines.append("| " + " | ".join(block.headers) + " |")
                lines.append("|" + "---|" * len(block.headers))
                lines += ["| " + " | ".join(format_value(v) for v in row) + " |" for row in block.rows]
                lines.append("")
            else:
                rel = os.path.relpath(block.path, out)
                lines += [f"![{block.caption}]({rel})", ""]
        return "\n".join(lines)


def _json_safe(value: Any) -> Any:
    """NaN/inf become null: metrics.json stays strict JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if hasattr(value, "item") and callable(value.item):  # numpy scalars
        return _json_safe(value.item())
    return value
