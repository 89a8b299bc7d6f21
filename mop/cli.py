"""The `mop` command. Subcommands live in `mop.commands.*`, one module each, each exposing
`register(subparsers)`; they are discovered here so adding a command never edits this file."""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

import mop
import mop.commands


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mop", description="Computer puppetry by demonstration.")
    parser.add_argument("--version", action="version", version=f"mop {mop.__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(mop.commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"mop.commands.{info.name}")
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except (ValueError, TypeError, OSError) as error:
        # Bad input from the user: one clear line, no traceback.
        print(f"mop {args.command}: error: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
