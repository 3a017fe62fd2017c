"""The `millflow` command line.

Each sub-command lives in its own module of :mod:`millflow.commands` and exposes
``add_parser(subparsers)``, which registers the sub-command and sets ``func`` (a
callable taking the parsed arguments and returning an exit code). Sub-commands are
found by listing that package, so adding a command is adding a module.
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from millflow.errors import MillflowError


def build_parser() -> argparse.ArgumentParser:
    import millflow.commands as commands

    parser = argparse.ArgumentParser(
        prog="millflow",
        description="Population-balance simulation of grinding mills and circuits.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"millflow.commands.{info.name}")
        if hasattr(module, "add_parser"):
            module.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except MillflowError as err:
        print(f"millflow {args.command}: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
