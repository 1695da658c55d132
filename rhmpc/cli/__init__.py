"""The `rhmpc` console script.

Each subcommand lives in its own module of this package (``rhmpc.cli.simulate``, …) and exposes

``register(subparsers) -> None``
    adds its ``argparse`` parser and sets ``func=run`` as a default;
``run(args) -> int``
    does the work and returns the process exit code.

Bad input raises :class:`rhmpc.errors.UsageError` (or ``ValueError``/``OSError`` from the
libraries below); :func:`main` turns it into a one-line message on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from rhmpc import __version__
from rhmpc.errors import UsageError, one_line_warnings

#: Subcommand modules, in the order ``rhmpc --help`` lists them.
COMMANDS: tuple[str, ...] = (
    "simulate", "compare", "robots", "data", "bench", "predict", "tune", "export", "config",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rhmpc",
        description="Receding-horizon MPC with heart-motion prediction "
        "for robot-assisted beating-heart surgery research.",
    )
    parser.add_argument("--version", action="version", version=f"rhmpc {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        importlib.import_module(f"rhmpc.cli.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    try:
        with one_line_warnings(f"rhmpc {args.command}"):
            return int(args.func(args) or 0)
    except BrokenPipeError:
        # The reader went away (``rhmpc ... | head``): not an error of ours. Point stdout at
        # devnull so that the interpreter's final flush does not raise again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (UsageError, ValueError, OSError) as exc:
        text = " ".join(str(exc).split())  # one line, whatever the message holds
        print(f"rhmpc {args.command}: error: {text}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"rhmpc {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
