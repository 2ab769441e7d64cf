"""The `layerpilot` command.

One module per command group (``map``, ``layers``, ``depth``, ``sim``, ``nodes``,
``link``, ``plan``, ``eval``, ``view``, ``bench``), each with ``register(commands)`` adding its
sub-commands. Heavy imports happen inside the handlers so that ``layerpilot --help``
stays fast. ``python -m layerpilot.cli`` runs the same command (``__main__``).
"""

from __future__ import annotations

import argparse
import sys

from layerpilot.cli import bench, depth, eval, layers, link, map, nodes, plan, sim, view

GROUPS = (map, layers, depth, sim, nodes, link, plan, eval, view)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="layerpilot", description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    bench.register(commands)
    for group in GROUPS:
        group.register(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        return 130
    except (ValueError, FileNotFoundError) as exc:
        print(f"layerpilot: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # permissions, a full disk, a busy port: the user can act on the one line
        print(f"layerpilot: error: {exc}", file=sys.stderr)
        return 1
