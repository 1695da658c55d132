"""`rhmpc export`: the whole real-time controller of one robot and one set of settings, as C."""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from rhmpc.cli import COMMANDS
from rhmpc.errors import UsageError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export",
        help=COMMANDS["export"],
        description="Write OUTDIR: the whole controller in C, from a sensor sample and the "
        "encoders to the motor torques: the outlier gate, the one-step or generalized RLS "
        "predictor and the interpolation of its forecast (rhmpc_refresh); the observer, the "
        "output offset, the MPC (screening cascade, OSQP's generated solver, fallbacks, "
        "envelope) and the cancellation with the controller's model (rhmpc_step); a header "
        "documenting units and layouts, an example loop and a CMakeLists.txt. Build with: "
        "cmake -S OUTDIR -B BUILD && cmake --build BUILD.",
    )
    p.add_argument("outdir", metavar="OUTDIR", help="directory to write (created if needed; "
                   "must be empty unless --force)")
    p.add_argument("--robot", metavar="NAME|FILE.toml", help="a registered robot (rhmpc robots) "
                   "or a robot file (default: the config's, else phantom)")
    p.add_argument("--config", metavar="FILE.toml",
                   help="a run's settings (rhmpc simulate --config): its [mpc], [reference], "
                   "[loop] Ts and downsample, [observer], [mismatch], predictor and "
                   "predictor_settings are exported")
    p.add_argument("--predictor", choices=("one-step", "generalized"),
                   help="the predictor (default: the config's, else generalized)")
    p.add_argument("--rate", type=float, metavar="HZ", default=257.0,
                   help="the sensor's sample rate [Hz] (default 257, a sonomicrometer): a "
                   "sensor slower than every loop.downsample ticks refreshes the reference on "
                   "each sample, at its own rate; a faster one every downsample ticks")
    p.add_argument("--force", action="store_true",
                   help="write into a non-empty OUTDIR, replacing only the files the export "
                   "writes")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from rhmpc.control.export import ExportError, export_controller
    from rhmpc.experiment import RunConfig, load_config
    from rhmpc.experiment.assembly import deployable
    from rhmpc.runtime.build import TRANSPORT, write_transport

    config = load_config(args.config) if args.config else RunConfig()
    changes = {k: v for k, v in (("robot", args.robot), ("predictor", args.predictor)) if v}
    config = config.replace(**changes)
    outdir = Path(args.outdir)
    controller = deployable(config, args.rate)
    name = controller.mpc.arm.robot.name
    try:
        info = export_controller(controller, outdir, robot=name, force=args.force)
        transport = write_transport(outdir)
    except (ExportError, OSError) as exc:
        raise UsageError(str(exc)) from None
    q, ref = controller.mpc.qp, controller.reference
    build = shlex.quote(str(outdir.with_name(outdir.name + "-build")))
    src = shlex.quote(str(outdir))
    print(f"rhmpc export: {name}, {config.predictor} predictor every {1e3 * ref.dt:g} ms, "
          f"N = {q.N}, {q.P.shape[0]} QP variables (RHMPC_NV: {q.nz} block inputs, "
          f"{q.P.shape[0] - q.nz} envelope slacks), {q.A.shape[0]} constraints, "
          f"{len(info.files) + len(transport)} files in {outdir} (key {info.key})")
    for note in info.notes:
        print(f"note:  {note}")
    print(f"build: cmake -S {src} -B {build} && cmake --build {build}")
    print(f"run:   {build}/rhmpc_example 2    (a fixed-rate loop with a fake sensor)")
    print(f"API:   {outdir / 'rhmpc.h'} (units and array layouts)")
    print(f"udp:   {outdir / TRANSPORT} (the controller's real-time program over the wire format "
          "and a robot-side client: cmake -S it; rhmpc sil runs it)")
    return 0
