"""The `mop` command. Subcommands live in `mop.commands.*`, one module each, each exposing
`register(subparsers)`; they are discovered here so adding a command never edits this file.

Errors: whatever goes wrong in a command is printed as one line, `mop CMD: error: ...`, with
exit code 1 (`CommandError` may choose another); `mop --debug CMD ...` shows the traceback
instead. Ctrl-C exits 130; a closed stdout (`mop takes list | head`) exits quietly.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import os
import pkgutil
import sys

import mop
import mop.commands
from mop.commands._args import CommandError

# exceptions that mean "the input was wrong", printed as their message alone; any other type
# is a fault in mop or in a library, printed with its type name so it can be reported
_USER_ERRORS = (ValueError, TypeError, OSError, KeyError)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mop", description="Computer puppetry by demonstration.")
    parser.add_argument("--version", action="version", version=f"mop {mop.__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback of an error (and debug logging)")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(mop.commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"mop.commands.{info.name}")
        module.register(subparsers)
    return parser


def describe_error(error: BaseException) -> str:
    """One line saying what went wrong, for a person: the message of a user error, the type and
    message of anything else."""
    if isinstance(error, OSError) and error.strerror and error.filename is not None:
        text = f"{error.filename}: {error.strerror}"
        if error.filename2 is not None:
            text += f" (-> {error.filename2})"
    elif isinstance(error, KeyError) and len(error.args) == 1 and isinstance(error.args[0], str):
        text = error.args[0]        # str(KeyError) would quote the message
    elif isinstance(error, MemoryError):
        text = "out of memory" + (f": {error}" if str(error) else "")
    elif isinstance(error, (CommandError, *_USER_ERRORS)):
        text = str(error) or type(error).__name__
    else:
        text = f"{type(error).__name__}: {error}" if str(error) else type(error).__name__
    text = " ".join(text.split())   # one line, whatever the message held
    return text if len(text) <= 2000 else text[:1997] + "..."


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    debug = args.debug or os.environ.get("MOP_DEBUG", "") not in ("", "0")
    if debug:
        logging.basicConfig(level=logging.DEBUG)
    else:
        # OpenCV's own warnings (a frame per line when a disk fills) would bury our one line
        os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader of our output went away (`mop takes list | head`): nothing to say
        try:
            sys.stdout = open(os.devnull, "w")
        except OSError:
            pass
        return 141
    except SystemExit:
        raise
    except BaseException as error:  # every failure: one line, or the traceback with --debug
        if debug:
            raise
        code = error.exit_code if isinstance(error, CommandError) else 1
        hint = "" if isinstance(error, (CommandError, *_USER_ERRORS)) else \
            " (run `mop --debug ...` for the traceback)"
        print(f"mop {args.command}: error: {describe_error(error)}{hint}", file=sys.stderr)
        return code


if __name__ == "__main__":
    sys.exit(main())
