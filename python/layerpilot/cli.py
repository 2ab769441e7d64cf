"""The `layerpilot` command.

Each package that offers commands has a ``commands`` module with
``register(commands, benches)``: it adds its sub-commands to ``commands`` and
its speed measurements to ``benches`` (``layerpilot bench <name>``). Heavy
imports happen inside the handlers so that ``layerpilot --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import sys

COMMAND_MODULES = [
    "layerpilot.map.commands",
    "layerpilot.layers.commands",
    "layerpilot.depth.commands",
    "layerpilot.sim.commands",
    "layerpilot.nodes.commands",
    "layerpilot.link.commands",
    "layerpilot.eval.commands",
]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="layerpilot", description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    bench = commands.add_parser("bench", help="speed measurements side by side with the reference")
    benches = bench.add_subparsers(dest="bench", required=True, metavar="WHAT")
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(commands, benches)
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


if __name__ == "__main__":
    sys.exit(main())
