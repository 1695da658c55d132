"""`rhmpc data`: list, show, export and plot heart-motion scenarios and recordings.

``rhmpc data list``                 the named scenarios: what each replicates, its targets
``rhmpc data list --measure``       … and their statistics measured on the synthetic motion
``rhmpc data show NAME``            p-p, RMS, heart-rate range, spectral peaks, predictability
``rhmpc data export NAME FILE``     write the motion (or a sensor's samples) to .csv/.npz
``rhmpc data plot NAME FILE.png``   position per axis over time, heart rate and PSD

NAME is a scenario name or the path of a recording (.csv/.npz/.mat; for .mat: ``--var``,
``--rows``/``--cols``, ``--rate``, ``--units``; a ROS bag: ``--topic``, ``--frame``, whose
``show`` without ``--topic`` lists its topics). Millimetres appear only here.

A scenario's motion is synthesised in memory, so a ``--duration`` (or ``--rate``) whose work
would not fit in the memory available is refused before any work, with the memory and time it
would take; long work that fits says how long it will take before it starts.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from rhmpc import io
from rhmpc.cli import COMMANDS
from rhmpc.errors import UsageError, one_line_warnings
from rhmpc.motion.tables import (
    measured_rows,
    measured_table,
    show_lines,
    spec_row,
    spec_table,
    stats_row,
)
from rhmpc.motion.targets import BPM_RANGE, Request, resolve
from rhmpc.sim.heart import DEFAULT_SCENARIO, SCENARIOS, SPECS
from rhmpc.sim.heart.scenarios import DEFAULT_SEED, missing_data
from rhmpc.sim.recordings import parse_indices
from rhmpc.sim.sensors import SENSORS


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``rhmpc data`` and its actions."""
    parser = subparsers.add_parser(
        "data", help=COMMANDS["data"],
        description="Heart-motion scenarios (synthetic replicas of the papers' data sets) "
        "and recordings: statistics, export and figures.")
    actions = parser.add_subparsers(dest="action", metavar="ACTION")
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--seed", type=int, default=None,
                        help=f"seed of the beat-to-beat variability (default {DEFAULT_SEED})")
    common.add_argument("--duration", type=float, help="seconds to use (default: the scenario's)")
    common.add_argument("--bpm", type=float, help="constant heart rate [beats/min] "
                        f"({BPM_RANGE[0]:g}–{BPM_RANGE[1]:g})")
    common.add_argument("--record", help="PhysioNet record whose annotated beats drive the "
                        "heart: a shipped name (mitdb-100, 1003) or a path without extension")
    common.add_argument("--var", help="MATLAB variable holding the positions (.mat files)")
    common.add_argument("--rows", type=parse_indices, help="0-based rows holding x,y,z (.mat)")
    common.add_argument("--cols", type=parse_indices, help="0-based columns holding x,y,z (.mat)")
    common.add_argument("--units", choices=("mm", "m", "um", "cm"),
                        help="length unit when the file does not state it (a CSV file's "
                        "default is mm; an NPZ or MAT file needs it)")
    common.add_argument("--topic", help="a ROS bag's topic to read (show lists them)")
    common.add_argument("--frame", help="the child frame read from a ROS bag's tf topic")
    common.add_argument("--poi", type=int, help="which of several tracked points is read, from 1")

    p_list = actions.add_parser(
        "list", parents=[common], help="the scenarios: what they replicate, their targets",
        description="The named scenarios and their calibration targets, at once. --measure "
        "(implied by --duration, --seed, --bpm and --record) also synthesises each one and "
        "measures its statistics (several seconds).")
    p_list.add_argument("--measure", action="store_true",
                        help="also measure each scenario's statistics on its motion")
    p_list.add_argument("--json", action="store_true", help="machine-readable output")

    p_show = actions.add_parser("show", parents=[common], help="statistics of one scenario/file")
    p_show.add_argument("name", nargs="?", default=DEFAULT_SCENARIO,
                        help=f"scenario or recording file (default {DEFAULT_SCENARIO})")
    p_show.add_argument("--json", action="store_true", help="machine-readable output")
    p_show.add_argument("--rate", type=float, help="sample rate of a .mat file without sample "
                        "times [Hz]")

    p_exp = actions.add_parser("export", parents=[common], help="write a scenario to .csv/.npz")
    p_exp.add_argument("name", help="scenario or recording file")
    p_exp.add_argument("file", help="output .csv (s, mm) or .npz (s, m)")
    p_exp.add_argument("--rate", type=float, help="sample rate [Hz] (default: the sensor's; for "
                       "a .mat file without sample times also its rate)")
    p_exp.add_argument("--sensor", choices=SENSORS,
                       help="write this sensor's noisy samples instead of the true motion")
    p_exp.add_argument("--force", action="store_true", help="overwrite an existing file")

    p_plot = actions.add_parser("plot", parents=[common], help="figure: position and PSD")
    p_plot.add_argument("name", help="scenario or recording file")
    p_plot.add_argument("file", help="output image (.png, .pdf, .svg)")
    p_plot.add_argument("--rate", type=float, help="sample rate of a .mat file without sample "
                        "times [Hz]")
    p_plot.add_argument("--window", type=float, default=10.0,
                        help="length of the zoomed time window of a long record [s] (default "
                        "%(default)s; a record up to twice as long is drawn whole)")
    p_plot.add_argument("--start", type=float, default=0.0,
                        help="start of the zoomed window [s] (default %(default)s)")
    parser.set_defaults(func=run, action=None)


def run(args: argparse.Namespace) -> int:
    """Dispatch to the action; a recording's warnings (``RecordingWarning``) are printed one
    line each."""
    if args.action is None:
        raise UsageError("choose an action: list, show, export or plot")
    action = {"list": _list, "show": _show, "export": _export, "plot": _plot}[args.action]
    with one_line_warnings("rhmpc data"):
        return action(args)


def _list(args: argparse.Namespace) -> int:
    """The scenarios' specifications, or (``--measure``) their measured statistics."""
    measure = args.measure or any(getattr(args, k) is not None
                                  for k in ("duration", "seed", "bpm", "record"))
    if any(getattr(args, k) is not None for k in ("var", "rows", "cols", "units", "topic",
                                                  "frame", "poi")):
        raise UsageError("--var, --rows, --cols, --units, --topic, --frame and --poi apply to "
                         "recordings, not to list")
    names = []
    for name in SCENARIOS:
        if (missing := missing_data(name)) is not None:
            print(f"# {name}: skipped, needs {missing}", file=sys.stderr)
            continue
        names.append(name)
    rows = (measured_rows(names, Request.of(args)) if measure
            else [spec_row(SPECS[n]) for n in names])
    if args.json:
        print(json.dumps(rows, indent=2))
    elif measure:
        print("\n".join(measured_table(rows)))
    else:
        print("\n".join(spec_table(rows)))
    return 0


def _show(args: argparse.Namespace) -> int:
    from rhmpc.sim.recordings import is_bag, survey, survey_lines

    bag = survey(args.name) if is_bag(args.name) else None  # its topics, then one's motion
    if bag is not None and args.topic is None:
        print(json.dumps(bag, indent=2) if args.json else "\n".join(survey_lines(bag)))
        return 0
    target = resolve(args.name, Request.of(args))
    row = stats_row(target) | ({"bag": bag} if bag else {})
    invivo = args.name in SPECS and SPECS[args.name].heart == "invivo"
    if invivo:  # the in-vivo regime beside the recording it was built from
        from rhmpc.sim.heart.invivo import source_statistics

        row["regime"] = source_statistics(target.source, target.duration)
    if args.json:
        print(json.dumps(row, indent=2))
        return 0
    print("\n".join([*(survey_lines(bag) if bag else []), *show_lines(row)]))
    if invivo:
        from rhmpc.sim.heart.invivo import statistics_table

        print("  the in-vivo recording's statistics (rhmpc.sim.heart.invivo, sampled at 25 Hz):")
        print("\n".join(statistics_table(row["regime"])))
    return 0


def _export(args: argparse.Namespace) -> int:
    out = Path(args.file)
    if out.suffix.lower() not in {".csv", ".npz"}:
        raise UsageError(f"{out}: output must end in .csv or .npz")
    if out.exists() and not args.force:
        raise UsageError(f"{out} exists; pass --force to overwrite")
    io.check_output(out, inputs=[args.name])
    from rhmpc.motion.targets import export

    target = resolve(args.name, Request.of(args))
    n = export(target, out, args.rate, args.sensor, args.seed)
    print(f"wrote {n} samples of {target.name} to {out}")
    return 0


def _plot(args: argparse.Namespace) -> int:
    from rhmpc.motion.figure import plot_motion

    if not (math.isfinite(args.window) and args.window > 0):
        raise UsageError(f"--window must be positive, got {args.window:g}")
    if not math.isfinite(args.start):
        raise UsageError(f"--start must be a number of seconds, got {args.start:g}")
    target = resolve(args.name, Request.of(args))
    plot_motion(target, Path(args.file), args.window, args.start)
    print(f"wrote {args.file}")
    return 0
