"""`rhmpc bench`: per-tick timing of the MPC on a moving reference, with same-run references."""

from __future__ import annotations

import argparse
import json
import sys

from rhmpc.bench.report import format_table
from rhmpc.bench.ticks import run_bench
from rhmpc.cli import COMMANDS
from rhmpc.cli.options import add_host_stalls_option, check_host_stalls, host_stalls_document
from rhmpc.control.settings import MPCSettings
from rhmpc.errors import UsageError
from rhmpc.robots import ROBOTS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "bench",
        help=COMMANDS["bench"],
        description="Run the MPC alone (closed loop with its linear model, not timed) on a "
        "heart-like reference with occasional jumps, and report per-tick p50/p99/max of the "
        "whole tick and its parts, OSQP iterations, fallbacks, and - measured in the same run - "
        "a precomputed-gain tick and an exact DAQP solve of the same QP, with the largest "
        "abs(u0 - u0_exact) / tau_max.",
    )
    p.add_argument("--ticks", type=int, default=20_000, help="timed ticks (default 20000)")
    p.add_argument("--warmup", type=int, default=500, help="untimed warm-up ticks (default 500)")
    p.add_argument("--robot", default="phantom", choices=ROBOTS, help="robot (default phantom)")
    p.add_argument("--seed", type=int, default=0, help="seed of the reference (default 0)")
    p.add_argument(
        "--jump-mm", type=float, default=2.0,
        help="reference jump size [mm] every --jump-every ticks (default 2; 0 = no jumps)",
    )
    p.add_argument("--jump-every", type=int, default=1000, help="ticks between jumps (1000)")
    p.add_argument(
        "--controller", choices=("python", "c"), default="python",
        help="'c' also runs the whole controller of `rhmpc export` (built once, cached; needs a "
        "C compiler) in a loop of its own on the same reference, every tick timed inside C, "
        "refresh ticks included",
    )
    p.add_argument(
        "--reading-delay", type=int, default=0, metavar="TICKS",
        help="with --controller c: each step takes the encoders' reading of TICKS ticks before "
        "(the observer fuses it there and predicts forward; default 0)",
    )
    p.add_argument("--gc", action="store_true", help="leave the garbage collector on in the loop")
    add_host_stalls_option(p, "the ticks")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.ticks < 1:
        raise UsageError(f"--ticks must be >= 1, got {args.ticks}")
    if args.warmup < 0:
        raise UsageError(f"--warmup must be >= 0, got {args.warmup}")
    if args.jump_mm < 0 or args.jump_every < 0:
        raise UsageError("--jump-mm and --jump-every must be >= 0")
    if args.reading_delay < 0 or (args.reading_delay and args.controller != "c"):
        raise UsageError("--reading-delay takes ticks >= 0, with --controller c")
    check_host_stalls(args.host_stalls)
    if args.controller == "c":
        from rhmpc.control.export import missing_toolchain

        reason = missing_toolchain()
        if reason:
            raise UsageError(reason)

    def progress(done: int, total: int) -> None:
        print(f"\rrhmpc bench: {done}/{total} ticks", end="", file=sys.stderr, flush=True)

    result = run_bench(
        robot=args.robot, ticks=args.ticks, seed=args.seed, settings=MPCSettings(),
        jump=args.jump_mm * 1e-3, jump_every=args.jump_every, warmup=args.warmup,
        disable_gc=not args.gc, progress=progress if sys.stderr.isatty() else None,
        controller=args.controller, reading_delay=args.reading_delay,
    )
    if sys.stderr.isatty():
        print(file=sys.stderr)
    if args.host_stalls > 0:
        result["host_stalls"] = host_stalls_document(args.host_stalls,
                                                     result["gain_tick_us"]["p50"])
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        print(format_table(result))
    return 0
