"""`rhmpc predict`: the prediction studies of Yuen et al. 2008 and Tuna et al. 2013, or every
predictor on the user's recordings (``--data``, :mod:`rhmpc.studies.recordings`)."""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from rhmpc import io
from rhmpc.cli import COMMANDS
from rhmpc.cli.simulate import add_recording_options, parse_split, recording_options
from rhmpc.errors import UsageError
from rhmpc.predictors import PREDICTORS
from rhmpc.sim.recordings.shipped import resolve_all
from rhmpc.studies.prediction import (
    BASE_BPM,
    DEFAULT_PREDICTORS,
    DEFAULT_TRIALS,
    STUDIES,
    StudySettings,
    format_table,
    parse_float_list,
    plot_study,
    run_study,
)
from rhmpc.studies.recordings import DEFAULT_LEADS, WARMUP_FRACTION, WARMUP_SECONDS

#: Options of the synthetic studies (``--study``) and of the recordings (``--data``).
STUDY_OPTIONS = ("trials", "noise_mm", "delta_bpm", "records", "scenarios")
DATA_OPTIONS = ("points", "poi", "split", "train", "save_models", "leads", "warmup", "latency",
                "var", "rows", "cols", "data_rate", "units")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "predict",
        help=COMMANDS["predict"],
        description="Monte Carlo prediction studies (--study). noise / hr-step / rr reproduce "
        "Yuen et al. 2008 §III-D (Tuna et al. 2013 Figs 12-13) on mitral-1d at 28 Hz: 30 s to "
        "initialise, then the RMS one-sample-ahead error against the truth over 10 s. horizon: "
        "RMS error versus lead time (Tuna Fig. 8) on sonomicrometry replicas at 7.5 ms. "
        "Or, with --data, every predictor on your recordings, open loop, each at the file's "
        "own rate: RMS and max forecast error at leads 1..L samples and at the lead the closed "
        "loop needs, ceil((period + latency + 25 ms horizon) / period), with hold and "
        "last-cycle as baselines; the first max(10 s, 25 % of the file) are a warm-up, not "
        "scored. With --poi N the predictors of point N that read the other tracked points "
        "get them; --split TRAIN:END runs the literature's protocol: the learned predictors "
        "are fitted on the frames before TRAIN (or on --train FILE...), every other one runs "
        "from the first frame, and the forecasts issued in [TRAIN, END) are scored. Before "
        "the fits start it says what it fits, on which frames, why each network is fitted "
        "twice (a validation round, then the final one) and about how long it will take, and "
        "which fitted predictors the default set leaves out (the GRUs, the slowest to fit) "
        "with the --predictors list that adds them.",
    )
    what = p.add_mutually_exclusive_group()
    what.add_argument("--study", choices=STUDIES, help="which synthetic study")
    what.add_argument("--data", nargs="+", metavar="FILE", help="recordings to score every "
                      "predictor on (CSV t,x,y,z in s and mm, NPZ, MATLAB .mat v5/v7.3, or "
                      "ROS bags with --topic)")
    p.add_argument(
        "--trials",
        type=int,
        default=None,
        help="Monte Carlo trials per value (default 100; horizon 10)",
    )
    p.add_argument("--jobs", type=int, default=1, help="worker processes (default 1; 0 = all CPUs)")
    p.add_argument("--seed", type=int, default=0, help="study seed; with --data, the seed of the "
                   "learned predictors' training (default 0)")
    p.add_argument(
        "--predictors",
        default=None,
        help="comma-separated predictor names (default: the study's set; with --data every "
        "predictor, the learned ones with --split or --train)",
    )
    p.add_argument(
        "--noise-mm", default=None, help="σ_R values for --study noise [mm], e.g. 0.3,1,3"
    )
    p.add_argument("--delta-bpm", default=None, help="ΔHR values for --study hr-step [bpm]")
    p.add_argument(
        "--records",
        default=None,
        help="comma-separated PhysioNet records for --study rr: shipped names (mitdb-100, "
        "1003) or paths without extension (default: every shipped record)",
    )
    p.add_argument("--scenarios", default=None, help="scenarios for --study horizon")
    p.add_argument(
        "--paper",
        choices=tuple(BASE_BPM),
        default="yuen2008",
        help="hr-step protocol: yuen2008 (base 60 bpm, default) or tuna2013 (base 103 bpm)",
    )
    g = p.add_argument_group("recordings (--data)")
    g.add_argument("--points", metavar="all|N[,N...]", help="files of several tracked points "
                   "(CSV t,x1,y1,z1,x2,...; NPZ (n, P, 3); MAT 3P x n): score every point and "
                   "their mean (all), or the points numbered from 1")
    g.add_argument("--poi", type=int, metavar="N", help="the point of interest (numbered from 1) "
                   "of a file of several tracked points: it is scored, and the predictors that "
                   "read the other points (st-rls, st-ridge, st-lstm, ...) get their past")
    g.add_argument("--split", metavar="TRAIN:END", help="the literature's protocol: fit the "
                   "learned predictors on the frames before TRAIN, score the forecasts issued "
                   "in [TRAIN, END) (frames from 0), e.g. 600:700")
    g.add_argument("--train", nargs="+", metavar="FILE", help="fit the learned predictors on "
                   "these recordings (same rate and layout; --poi applies) instead of the "
                   "frames before TRAIN")
    g.add_argument("--save-models", type=Path, metavar="DIR", help="write the fitted models "
                   "to this folder (LABEL.NAME.npz), to load later with the predictor "
                   "setting model=FILE")
    g.add_argument("--leads", type=int, help=f"score leads 1..L samples (default {DEFAULT_LEADS})")
    g.add_argument("--warmup", type=float, metavar="S", help="seconds not scored at the start "
                   f"(default: the longer of {WARMUP_SECONDS:g} s and "
                   f"{100 * WARMUP_FRACTION:g} %% of the file)")
    g.add_argument("--latency", type=float, metavar="S",
                   help="delivery latency of the samples [s], for the closed loop's lead "
                   "(default 0: each sample is available at its timestamp)")
    add_recording_options(p)
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.add_argument("--out", type=Path, default=None, help="write the result JSON to this file")
    p.add_argument("--plot", type=Path, default=None, help="draw the curves to this PNG file")
    p.set_defaults(func=run)


def _settings(args: argparse.Namespace) -> StudySettings:
    trials = DEFAULT_TRIALS[args.study] if args.trials is None else args.trials
    if trials < 1:
        raise UsageError(f"--trials must be >= 1, got {trials}")
    kw: dict = {"study": args.study, "trials": trials, "seed": args.seed, "paper": args.paper}
    if args.predictors:
        names = tuple(n.strip() for n in args.predictors.split(",") if n.strip())
        bad = [n for n in names if n not in PREDICTORS]
        if bad:
            raise UsageError(
                f"unknown predictor(s) {', '.join(bad)}; valid: {', '.join(PREDICTORS)}"
            )
        if "exact" in names and args.study != "horizon":
            raise UsageError("`exact` only makes sense in --study horizon")
        kw["predictors"] = names
    try:
        if args.noise_mm:
            kw["noise_mm"] = parse_float_list(args.noise_mm)
        if args.delta_bpm:
            kw["delta_bpm"] = parse_float_list(args.delta_bpm)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.records:
        recs = tuple(r.strip() for r in args.records.split(",") if r.strip())
        from rhmpc.sim.heart.rr import shipped_records

        missing = [r for r in recs if not _is_record(r)]
        if missing:
            raise UsageError(f"record(s) not found: {', '.join(missing)} (shipped: "
                             f"{', '.join(shipped_records())}, or a path without extension)")
        kw["records"] = recs
    if args.scenarios:
        from rhmpc.sim.heart import SCENARIOS

        scns = tuple(s.strip() for s in args.scenarios.split(",") if s.strip())
        bad = [s for s in scns if s not in SCENARIOS]
        if bad:
            raise UsageError(f"unknown scenario(s) {', '.join(bad)}; valid: {', '.join(SCENARIOS)}")
        kw["scenarios"] = scns
    s = StudySettings(**kw)
    if args.study == "rr" and not s.parameters():
        raise UsageError("--study rr needs --records (no shipped record found)")
    return s


def _is_record(name: str) -> bool:
    """Whether ``name`` resolves to a PhysioNet record (a path or a shipped name)."""
    from rhmpc.sim.heart.rr import find_record

    try:
        find_record(name)
    except ValueError:
        return False
    return True


def _check_mode(args: argparse.Namespace) -> None:
    """One of --study and --data, and only the options of that one."""
    def flags(names):
        return [f"--{n.replace('_', '-')}".replace("--data-rate", "--rate") for n in names
                if getattr(args, n, None) is not None]

    if args.data is None and args.study is None:
        raise UsageError("choose --study NAME (a synthetic study) or --data FILE [FILE ...] "
                         "(your recordings)")
    if args.data is not None and (bad := flags(STUDY_OPTIONS)):
        raise UsageError(f"{', '.join(bad)} apply to --study, not --data")
    if args.study is not None and (bad := flags(DATA_OPTIONS)):
        raise UsageError(f"{', '.join(bad)} apply to --data FILE, not --study")


def _check_outputs(args: argparse.Namespace) -> None:
    """--out and --plot can be written and are none of the inputs, before any work."""
    inputs = [*(args.data or []), *(args.train or [])] if args.data is not None else []
    for option in ("out", "plot"):
        if getattr(args, option) is not None:
            io.check_output(getattr(args, option), f"--{option}", inputs=inputs)


def run(args: argparse.Namespace) -> int:
    _check_mode(args)
    _check_outputs(args)
    if args.data is not None:
        return _run_data(args)
    s = _settings(args)
    jobs = (os.cpu_count() or 1) if args.jobs == 0 else args.jobs
    if jobs < 1:
        raise UsageError(f"--jobs must be >= 0, got {args.jobs}")
    values = len(s.parameters())
    io.check(f"{s.study} trials", s.trials, "--trials", memory_scale=values,
                   time_scale=values * len(s.names), workers=jobs)
    bar = None
    if sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(
            total=len(s.parameters()) * s.trials,
            desc=f"predict {s.study}",
            unit="trial",
            file=sys.stderr,
        )

        def progress(done: int, total: int) -> None:
            bar.update(done - bar.n)
    else:

        def progress(done: int, total: int) -> None:
            if done == total or done % max(1, total // 10) == 0:
                print(f"rhmpc predict: {done}/{total} trials", file=sys.stderr, flush=True)

    result = run_study(s, jobs=jobs, progress=progress)
    if bar is not None:
        bar.close()
    _publish(args, result, plot_study, format_table)
    if not args.json:
        print(
            f"({result['elapsed_s']:.1f} s, {jobs} job(s); default predictors "
            f"{','.join(DEFAULT_PREDICTORS[s.study])})",
            file=sys.stderr,
        )
    return 0


def _run_data(args: argparse.Namespace) -> int:
    """``--data``: every predictor on the recordings, open loop (rhmpc.studies.recordings)."""
    from functools import partial

    from rhmpc.sim.recordings import training_series
    from rhmpc.sim.recordings.formats import check_source
    from rhmpc.studies.recordings import OpenLoopSettings, run_open_loop
    from rhmpc.studies.recordings_report import format_report, plot_leads
    from rhmpc.studies.tracks import load_tracks, parse_points, poi_tracks

    names = tuple(n.strip() for n in (args.predictors or "").split(",") if n.strip())
    if args.poi is not None and args.points is not None:
        raise UsageError("--poi N scores point N with the others as side information; "
                         "--points scores points one by one: choose one")
    if args.poi is not None and args.poi < 1:
        raise UsageError(f"--poi {args.poi}: points are numbered from 1")
    split = parse_split(args.split)
    try:
        settings = OpenLoopSettings(
            predictors=names, leads=DEFAULT_LEADS if args.leads is None else args.leads,
            warmup=args.warmup, latency=0.0 if args.latency is None else args.latency,
            split=split, seed=args.seed)
        files, read, poi = resolve_all(args.data, recording_options(args))
        if args.poi is not None or (poi is not None and args.points is None):
            args.poi = poi if args.poi is None else args.poi
            tracks = poi_tracks(files, args.poi, read)
        else:
            tracks = load_tracks(files, parse_points(args.points), read)
        train = None
        if args.train:
            for f in args.train:  # each a file (or a bag's folder) the one reader takes
                check_source(f)
            train = partial(training_series, args.train, args.poi, read)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if args.save_models is not None:
        if split is None and train is None:
            raise UsageError("--save-models needs --split TRAIN:END or --train FILE...")
        io.make_folder(args.save_models, root=args.save_models)

    def progress(what: str) -> None:
        if not args.json:
            print(f"rhmpc predict: {what}", file=sys.stderr, flush=True)

    try:
        doc = run_open_loop(tracks, settings, progress, train, args.save_models)
    except (ValueError, ImportError) as exc:
        raise UsageError(str(exc)) from None
    _publish(args, doc, plot_leads, format_report)
    return 0


def _publish(args: argparse.Namespace, doc: dict, plot, text) -> None:
    """The document to ``--out``, its figure to ``--plot``, and to stdout as JSON (``--json``)
    or as ``text(doc)``."""
    if args.out:
        io.write_text(args.out, json.dumps(doc, indent=2) + "\n")
    if args.plot:
        plot(doc, args.plot)
    print(json.dumps(doc, indent=2) if args.json else text(doc))
