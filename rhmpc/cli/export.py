"""`rhmpc export`: the controller of one robot and one set of settings as a C library."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from rhmpc.errors import UsageError
from robots import ROBOTS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help="write the MPC as a self-contained C library (OSQP codegen + the tick)",
        description="Write OUTDIR: the controller's tick in C (screening, shifted warm start, "
        "fallback chain plan -> LQ -> zero, torque clipping), OSQP's generated solver for its QP "
        "(vectors mode), its numbers as const arrays from the same CondensedQP the Python "
        "controller uses, a header documenting units and layouts, and a CMakeLists.txt. Build "
        "with: cmake -S OUTDIR -B BUILD && cmake --build BUILD.",
    )
    p.add_argument("outdir", metavar="OUTDIR", help="directory to write (created if needed)")
    p.add_argument("--robot", choices=ROBOTS,
                   help="robot (default: the config's, else phantom)")
    p.add_argument("--config", metavar="FILE.toml",
                   help="a run's settings (rhmpc simulate --config); its [mpc] and loop.Ts are "
                   "exported")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from rhmpc.control.export import ExportError, export_controller
    from rhmpc.control.mpc import RecedingHorizonMPC
    from rhmpc.experiment import RunConfig, load_config
    from robots import linearize, load_robot

    config = load_config(args.config) if args.config else RunConfig()
    robot = args.robot or config.robot
    outdir = Path(args.outdir)
    if outdir.exists() and not outdir.is_dir():
        raise UsageError(f"{outdir}: exists and is not a directory")
    mpc = RecedingHorizonMPC(linearize(load_robot(robot), Ts=config.loop.Ts), config.mpc)
    try:
        info = export_controller(mpc, outdir, robot=robot)
    except ExportError as exc:
        raise UsageError(str(exc)) from None
    q = mpc.qp
    build = shlex.quote(str(outdir.with_name(outdir.name + "-build")))
    src = shlex.quote(str(outdir))
    print(f"rhmpc export: {robot}, N = {q.N}, {q.nz} QP variables, {q.A.shape[0]} constraints, "
          f"{len(info.files)} files in {outdir} (key {info.key})")
    for note in info.notes:
        print(f"note:  {note}")
    print(f"build: cmake -S {src} -B {build} && cmake --build {build}")
    print(f"API:   {outdir / 'rhmpc.h'} (units and array layouts)")
    return 0
