"""The `rhmpc` console script.

Each subcommand lives in its own module of this package (``rhmpc.cli.simulate``, …) and exposes

``register(subparsers) -> None``
    adds its ``argparse`` parser and sets ``func=run`` as a default;
``run(args) -> int``
    does the work and returns the process exit code.

Bad input raises :class:`rhmpc.errors.UsageError` (or ``ValueError``/``OSError`` from the
libraries below); :func:`main` turns it into a one-line message on stderr and exit code 2,
as it does a ``MemoryError`` (a setting or an input that sizes an array beyond the machine).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from rhmpc.errors import UsageError, one_line, one_line_warnings

#: Subcommands (modules of this package), in the order ``rhmpc --help`` lists them, with
#: their one-line help.
COMMANDS: dict[str, str] = {
    "simulate": "run the closed loop once and print its tracking summary",
    "compare": "predictors x scenarios (or recordings) in parallel; --paper sets them beside "
    "Tuna et al.'s Tables I–III",
    "robots": "list the registered robots",
    "data": "list, show, export and plot heart-motion scenarios",
    "bench": "time the MPC tick against a gain tick and an exact active-set solve",
    "predict": "the predictors open loop: on recordings (--data) or in prediction studies",
    "tune": "sweep settings (MPC weights, predictor order, downsampling...) in parallel, "
    "resumably; 'tune report' ranks the results",
    "export": "write the real-time controller as a self-contained C library",
    "sil": "the deployment in real time: sensor, predictor, exported controller and robot as "
    "processes over UDP",
    "config": "show every setting of a run (TOML that --config reads back)",
}


class _Version(argparse.Action):
    """``--version``: the installed version, read only when asked (see ``rhmpc.__version__``)."""

    def __init__(self, option_strings, dest=argparse.SUPPRESS, **kwargs) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS,
                         help="show the version and exit")

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        import rhmpc
        print(f"rhmpc {rhmpc.__version__}")  # on standard output, as argparse's own
        parser.exit()


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of every subcommand; with ``command``, that one's in full and the others by
    name and help only, so that a command loads only its own modules (and what they import)."""
    parser = argparse.ArgumentParser(
        prog="rhmpc",
        description="Receding-horizon MPC with heart-motion prediction "
        "for robot-assisted beating-heart surgery research.",
    )
    parser.add_argument("--version", action=_Version)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, summary in COMMANDS.items():
        if command in (None, name):
            importlib.import_module(f"rhmpc.cli.{name}").register(sub)
        else:
            sub.add_parser(name, help=summary)
    return parser


#: OpenBLAS's threads for the command's process and its workers, unless the environment sets
#: them: rhmpc's matrices are small, and the threads spin between calls for more processor time
#: than they save (docs/design/decisions/blas-threads.md).
BLAS_THREADS = "1"


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", BLAS_THREADS)  # before numpy loads OpenBLAS
    argv = sys.argv[1:] if argv is None else list(argv)
    command = argv[0] if argv and argv[0] in COMMANDS else ""
    parser = build_parser(command)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    from rhmpc.io import tracking_inputs

    try:
        with one_line_warnings(f"rhmpc {args.command}"), tracking_inputs():
            return int(args.func(args) or 0)
    except BrokenPipeError:
        # The reader went away (``rhmpc ... | head``): not an error of ours. Point stdout at
        # devnull so that the interpreter's final flush does not raise again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except (UsageError, ValueError, OSError) as exc:
        # one line of a readable length, whatever the message holds
        print(f"rhmpc {args.command}: error: {one_line(exc)}", file=sys.stderr)
        return 2
    except MemoryError as exc:  # a setting or an input that sizes an array beyond the machine
        text = one_line(exc)
        print(f"rhmpc {args.command}: error: out of memory{f' ({text})' if text else ''}: a "
              "setting or an input asks for more than this machine has", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"rhmpc {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
