"""`rhmpc simulate`: one closed-loop run — heart, sensor, predictor, MPC, Pinocchio plant."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rhmpc.cli import COMMANDS
from rhmpc.cli.options import (
    SETTLING_RULE,
    add_host_stalls_option,
    add_model_option,
    add_recording_options,
    add_run_options,
    add_split_option,
    check_host_stalls,
    host_stalls_document,
    parse_split,
    recording_options,
)
from rhmpc.errors import UsageError

if TYPE_CHECKING:  # the run's stack loads when a run starts, not for --help
    from rhmpc.experiment import RunConfig


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate", help=COMMANDS["simulate"],
        description="Closed loop at 2 kHz: heart motion -> sensor -> predictor (every "
        "downsample ticks) -> cubic interpolation to 50 reference points -> MPC (OSQP) -> "
        "nonlinearity cancellation -> Pinocchio plant. Prints RMS/max tracking error, RMS "
        "control effort, prediction error and per-tick controller timing.")
    p.add_argument("--predictor", help="predictor name (default generalized; 'exact' = the true "
                   "future)")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--scenario", help="heart-motion scenario (rhmpc data list); default "
                     "fixed-a2-top")
    src.add_argument("--data", metavar="FILE", help="a recording (CSV t,x,y,z in s and mm, NPZ, "
                     "MATLAB .mat v5/v7.3, or a ROS bag: a rosbag2 folder, .mcap, .db3, ROS 1 "
                     ".bag); runs the whole recording unless --duration")
    add_recording_options(p)
    p.add_argument("--poi", type=int, metavar="N", help="the point of interest (numbered from 1) "
                   "of a --data file of several tracked points; a predictor that reads the "
                   "other points (st-rls, st-ridge, st-lstm, ...) gets their samples")
    add_split_option(p)
    add_model_option(p)
    p.add_argument("--train", nargs="+", metavar="FILE", help="recordings a predictor fitted "
                   "before the run (ridge, lstm, ...) learns from, beside the run's own "
                   "settling window (same rate and layout; --poi applies)")
    p.add_argument("--seed", type=int, help="seed of every random draw (default 0)")
    p.add_argument("--controller", choices=("python", "c"), default="python",
                   help="who refreshes the reference: the run's predictor in Python (default), "
                   "or 'c', the controller library's own RLS predictor, as on a target with no "
                   "predictor process (one-step, generalized); the tick is the same library")
    add_run_options(p)
    p.add_argument("--out", metavar="FILE", help="write the result document: FILE.json, or "
                   "FILE.mat for MATLAB (the summary and the trace: time, error, ee, poi, "
                   "torques, forecasts)")
    p.add_argument("--json", action="store_true", help="print the result document on stdout")
    p.add_argument("--plot", metavar="FILE.png", help="figures: per axis the POI, the tool and "
                   "the 25-ms forecasts against the measured samples; the error; the torques "
                   "against their limits (PNG, or vector PDF/SVG)")
    p.add_argument("--figure", choices=("dashboard", "paper"), default="dashboard",
                   help="what --plot draws: dashboard (default: every axis, the error and the "
                   "torques over the run, a zoom and a detail) or paper (one column wide: the "
                   "tracking error over the run, and the POI against the tool with the "
                   "forecasts; its numbers are the summary's)")
    p.add_argument("--view", metavar="FILE.html", help="a 3-D replay of the run: one "
                   "self-contained page that opens offline (the arm, the POI's and the tool's "
                   "paths, the forecasts; play, pause, time slider)")
    p.add_argument("--trace", metavar="FILE.npz", help="write every tick to an NPZ file as the "
                   "run goes (chunked; read it with rhmpc.sim.loop.trace.read_trace)")
    add_host_stalls_option(p, "the run")
    from rhmpc.sim.sensors.faults import GRAMMAR

    p.add_argument("--fault", action="append", default=[], metavar="KIND@START[:ARG…]",
                   help=f"inject a fault into the run (repeatable; the truth is untouched): "
                   f"{GRAMMAR}; e.g. --fault freeze@14:0.3 --fault jump@20:5mm. The summary "
                   "states each fault's errors and counts")
    p.set_defaults(func=run)


#: Options that set one setting each: option → the setting.
OPTIONS = {"predictor": "predictor", "scenario": "scenario", "data": "data", "seed": "seed",
           "robot": "robot", "sensor": "sensor", "rr": "rr", "ground_truth": "ground_truth",
           "train": "train", "duration": "loop.duration", "settling": "loop.settling"}


def config_from_args(args: argparse.Namespace) -> RunConfig:
    """The run's settings (:func:`rhmpc.experiment.config.run_config`): defaults < --config
    file < --preset < explicit options < --set."""
    from rhmpc.experiment.config import run_config

    options = {key: getattr(args, name) for name, key in OPTIONS.items()
               if getattr(args, name, None) is not None}
    if getattr(args, "data", None):
        options["data_read"] = recording_options(args)
        if getattr(args, "poi", None) is not None:
            options["data_read"]["point"] = args.poi
    elif any(getattr(args, k, None) is not None
             for k in ("var", "rows", "cols", "data_rate", "units", "topic", "frame", "poi",
                       "split")):
        raise UsageError("--var, --rows, --cols, --rate, --units, --topic, --frame, --poi and "
                         "--split need --data FILE")
    if options.get("train"):
        options["train"] = tuple(options["train"])
    return run_config(args.config, getattr(args, "preset", None), options, args.set,
                      getattr(args, "fault", None) or (), getattr(args, "model", None) or (),
                      parse_split(getattr(args, "split", None)))


def settling_rule(args: argparse.Namespace) -> str:
    """Where the run's settling time came from, for the summary."""
    if getattr(args, "split", None):
        train, end = parse_split(args.split)
        return f"the samples before {train} of --split {train}:{end}"
    if getattr(args, "settling", None) is not None:
        return "set by --settling"
    if getattr(args, "config", None):
        return f"from {args.config}"
    return SETTLING_RULE


#: What each output option writes, by its file's suffix.
OUTPUTS = {"out": (".json", ".mat"), "plot": (".png", ".pdf", ".svg"), "view": (".html",),
           "trace": (".npz",)}


def check_outputs(args: argparse.Namespace, inputs=()) -> None:
    """Every output file can be written, checked before the run starts (a missing or
    read-only directory, a suffix the option does not write, a link, or one of ``inputs``, the
    run's files, is a one-line error: :func:`rhmpc.io.check_output`)."""
    from rhmpc import io

    for option, suffixes in OUTPUTS.items():
        path = getattr(args, option, None)
        if not path:
            continue
        path = Path(path)
        if path.suffix.lower() not in suffixes:
            raise UsageError(f"--{option} {path}: the file must end in "
                             f"{' or '.join(suffixes)}")
        io.check_output(path, f"--{option}", inputs=inputs)


def check_score(doc: dict) -> None:
    """A run whose score is not finite says why (exit 2)."""
    rms = doc.get("rms_error_mm")
    if rms is not None and np.isfinite(rms):
        return
    excluded = doc.get("excluded") or {}
    raise UsageError(
        f"the run has no finite score (RMS {rms}): no tick after the settling has a finite "
        f"error against the {doc.get('ground_truth')} motion ({excluded.get('unmeasured', 0)} "
        f"recorded samples are no measurements, {excluded.get('outliers', 0)} were taken as "
        "outliers); check the recording with rhmpc data show, or raise --duration")


def write_outputs(args: argparse.Namespace, result, doc: dict) -> None:
    """--out (JSON, or MATLAB's .mat), --plot and --view."""
    if args.out and Path(args.out).suffix.lower() == ".mat":
        from rhmpc.report.matlab import write_mat

        write_mat(args.out, result, doc)
    elif args.out:
        from rhmpc import io

        io.write_text(args.out, json.dumps(doc, indent=2) + "\n")
    if args.plot or getattr(args, "view", None):
        from rhmpc.robots import load_robot

        robot = load_robot(doc["robot"])
    if args.plot and getattr(args, "figure", "dashboard") == "paper":
        from rhmpc.report.paper_figure import plot_paper

        plot_paper(result, doc, args.plot)
    elif args.plot:
        from rhmpc.report.figures import plot_run

        plot_run(result, args.plot, title=f"{doc['predictor']} on {doc['scenario']} "
                 f"({doc['robot']}): RMS error {doc['rms_error_mm']:.3f} mm",
                 torque_limit=robot.torque_limit,
                 joint_names=[robot.model.names[j] for j in range(1, robot.nv + 1)],
                 score=doc)
    if getattr(args, "view", None):
        from rhmpc.report.replay import write_replay

        write_replay(args.view, result, robot, title=f"{doc['predictor']} on "
                     f"{doc['scenario']}: RMS error {doc['rms_error_mm']:.3f} mm")


def run(args: argparse.Namespace) -> int:
    config = config_from_args(args)
    from rhmpc.control.export import missing_toolchain

    if reason := missing_toolchain():
        raise UsageError(reason)
    from rhmpc.experiment import run_experiment
    from rhmpc.experiment.config import input_files

    check_outputs(args, [*input_files(config), *filter(None, [args.config])])
    trace = getattr(args, "trace", None)
    stalls = getattr(args, "host_stalls", 0.0)
    check_host_stalls(stalls)
    try:
        result, doc = run_experiment(config, progress=not args.json, trace=trace,
                                     gain_tick=True, implementation=args.controller)
    except ValueError as exc:
        if trace and str(exc).startswith(f"{trace}:"):  # the trace file cannot be written
            raise UsageError(str(exc)) from None
        raise
    check_score(doc)
    if getattr(args, "split", None):
        doc["split"] = list(parse_split(args.split))
    if stalls > 0:
        g = (doc.get("gain_tick_us") or {}).get("p50")
        doc["host_stalls"] = host_stalls_document(stalls, g)
    write_outputs(args, result, doc)
    if args.json:
        json.dump(doc, sys.stdout, indent=2)
        print()
        return 0
    from rhmpc.report.summary import format_summary

    print(format_summary(doc, settling_rule(args)))
    for option, what in (("out", "result"), ("plot", "figure"), ("view", "3-D replay"),
                         ("trace", "trace")):
        if getattr(args, option, None):
            print(f"  {what:<16} {getattr(args, option)}"
                  + (" (every tick)" if option == "trace" else ""))
    return 0
