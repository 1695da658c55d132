"""`rhmpc compare`: predictors × scenarios (or recordings) in parallel — the replica of Tuna et
al. Tables I/III, and the same table on the user's recordings (``--data``)."""

from __future__ import annotations

import argparse
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

from rhmpc.cli.simulate import (
    add_recording_options,
    add_run_options,
    config_from_args,
    recording_options,
)
from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.studies.paper import COLUMNS

#: Tuna et al. Table I/II column order (fixed rate: animals 1, 2; varying: 1, 3 top; 1, 3 side).
TABLE_SCENARIOS = COLUMNS
TABLE_PREDICTORS = ("exact", "one-step", "generalized", "ekf")
DEFAULT_DURATION = 60.0
DEFAULT_SETTLING = 20.0
#: Options that read a recording (``--data``); their ``argparse`` destinations.
READ_OPTIONS = ("var", "rows", "cols", "data_rate", "units")


@dataclass(frozen=True)
class Job:
    """One closed-loop run of the table.

    Attributes
    ----------
    column : str
        The table's column: a scenario, a recording (its file name), or one tracked point of
        it (``rec.mat:p2``).
    config : RunConfig
        The run's settings.
    """

    column: str
    config: RunConfig


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compare", help="predictors x scenarios (or recordings) in parallel: the Tuna Tables "
        "I/III replica",
        description="Run every predictor on every scenario (or recording, --data) in closed "
        "loop (parallel processes) and print RMS (max) position error and RMS control effort "
        "per predictor and column, with the ratio to the 'exact' row (to 'hold' without it).")
    p.add_argument("--predictors", default=",".join(TABLE_PREDICTORS),
                   help="comma-separated predictor names (default %(default)s)")
    p.add_argument("--scenarios",
                   help="comma-separated scenario names (default: the six Table-I replicas)")
    p.add_argument("--data", nargs="+", metavar="FILE", help="recordings instead of scenarios, "
                   "one column each (CSV t,x,y,z in s and mm, NPZ, MATLAB .mat); each runs "
                   "whole unless --duration, with the sensor 'recorded' unless --sensor")
    p.add_argument("--points", metavar="all|N[,N...]", help="files of several tracked points "
                   "(CSV t,x1,y1,z1,x2,...; NPZ (n, P, 3); MAT 3P x n): one column per point "
                   "(all) or per chosen point, numbered from 1")
    p.add_argument("--seeds", type=int, default=1,
                   help="seeds per cell: SEED..SEED+S-1 (default 1)")
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument("--paper", action="store_true",
                   help="also print Tuna et al. 2013's tables of the runs' setting beside ours "
                   "(Table I for a simulated plant, II-III for the hardware plant): paper, ours "
                   "and their ratio for every cell, and which published findings reproduce")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                   help="parallel processes (default: the number of cores)")
    p.add_argument("--full", action="store_true",
                   help="use each scenario's full duration (235-472 s) instead of --duration")
    add_run_options(p, DEFAULT_DURATION, DEFAULT_SETTLING)
    add_recording_options(p)
    p.add_argument("--json", action="store_true", help="print all result documents as JSON: "
                   "one per column, predictor and seed, each with scenario (the column: a "
                   "scenario, a file name, FILE:pN for a point), rms_error_mm, max_error_mm and "
                   "rms_effort_mNm")
    p.add_argument("--out", metavar="FILE.json", help="write all result documents")
    p.set_defaults(func=run)


def _one(job: Job) -> dict:
    config = job.config
    try:
        doc = run_experiment(config)[1]
    except Exception as exc:  # one failed cell must not lose the others
        doc = {"predictor": config.predictor, "seed": config.seed,
               "error": f"{type(exc).__name__}: {exc}"}
    doc["scenario"] = job.column
    if config.data is not None:
        doc["data"] = config.data
        doc["point"] = config.data_read.get("point")
    return doc


def configs(args: argparse.Namespace) -> list[RunConfig]:
    """One run configuration per predictor × scenario (or recording) × seed."""
    return [job.config for job in jobs(args)]


def jobs(args: argparse.Namespace) -> list[Job]:
    """One :class:`Job` per predictor × column × seed, in the table's order."""
    from predictors import PREDICTORS

    predictors = [p.strip() for p in args.predictors.split(",") if p.strip()]
    bad = [p for p in predictors if p not in PREDICTORS]
    if bad:
        raise UsageError(f"unknown predictor(s) {', '.join(bad)}; valid: {', '.join(PREDICTORS)}")
    if args.seeds < 1 or args.jobs < 1:
        raise UsageError("--seeds and --jobs must be >= 1")
    columns = _data_columns(args) if args.data else _scenario_columns(args)
    first_seed = args.seed
    base = _base_config(args)
    out = []
    for column, changes in columns:
        run_base = _with_duration(base.replace(**changes), args)
        for predictor in predictors:
            for seed in range(first_seed, first_seed + args.seeds):
                out.append(Job(column, run_base.replace(predictor=predictor, seed=seed)))
    return out


def _scenario_columns(args: argparse.Namespace) -> list[tuple[str, dict]]:
    """(column, settings) of each scenario."""
    from sim.heart import SCENARIOS, SPECS

    if args.points is not None or any(getattr(args, k, None) is not None
                                      for k in READ_OPTIONS):
        raise UsageError("--points, --var, --rows, --cols, --rate and --units need --data FILE")
    names = args.scenarios or ",".join(TABLE_SCENARIOS)
    scenarios = [s.strip() for s in names.split(",") if s.strip()]
    unknown = [s for s in scenarios if s not in SCENARIOS]
    if unknown:
        raise UsageError(f"unknown scenario(s) {', '.join(unknown)}; valid: {', '.join(SCENARIOS)}")
    return [(s, {"scenario": s, **({"loop.duration": SPECS[s].duration} if args.full else {})})
            for s in scenarios]


def _data_columns(args: argparse.Namespace) -> list[tuple[str, dict]]:
    """(column, settings) of each recording, or of each tracked point with --points."""
    from rhmpc.studies.recordings import file_points, parse_points

    if args.scenarios is not None or args.full or args.paper:
        raise UsageError("--scenarios, --full and --paper apply to scenarios, not --data")
    read = recording_options(args)
    try:
        files = file_points(args.data, parse_points(args.points), read)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    sensor = {} if args.sensor else {"sensor": "recorded"}
    out = []
    for group in files:
        for column, path, point, recording in group:
            changes = {"data": path, "data_read": {**read, **({"point": point} if point else {})},
                       **sensor}
            if args.duration is None and not args.config:  # default: the whole recording
                changes["loop.duration"] = recording.duration
            elif args.duration is not None and args.duration > recording.duration:
                raise UsageError(f"{path}: the recording lasts {recording.duration:.2f} s, "
                                 f"--duration asks for {args.duration:.2f} s")
            out.append((column, changes))
    return out


def _base_config(args: argparse.Namespace) -> RunConfig:
    """The settings every run shares: defaults < --config < --preset < options < --set."""
    saved = {k: getattr(args, k, None) for k in ("predictor", "scenario", "data", "seed",
                                                 "duration", "settling", *READ_OPTIONS)}
    for key in saved:
        setattr(args, key, None)
    try:
        base = config_from_args(args)
    finally:
        for key, value in saved.items():
            setattr(args, key, value)
    if not args.config:
        base = base.replace(**{"loop.duration": DEFAULT_DURATION,
                               "loop.settling": DEFAULT_SETTLING})
    return base


def _with_duration(config: RunConfig, args: argparse.Namespace) -> RunConfig:
    """--duration and --settling applied: the settling defaults to min(20 s, duration / 3)
    when the duration is given or set by a recording's length."""
    duration = config.loop.duration if args.duration is None or args.full else args.duration
    if args.settling is not None:
        settling = args.settling
    elif args.duration is not None or (args.data and not args.config):
        settling = min(DEFAULT_SETTLING, (args.duration or duration) / 3)
    else:
        settling = config.loop.settling
    return config.replace(**{"loop.duration": duration, "loop.settling": settling})


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from rhmpc.studies.comparison import comparison_table

    todo = jobs(args)
    runs = [job.config for job in todo]
    predictors = list(dict.fromkeys(c.predictor for c in runs))
    columns = list(dict.fromkeys(job.column for job in todo))
    docs: list[dict] = [{} for _ in todo]
    with ProcessPoolExecutor(max_workers=min(args.jobs, len(todo))) as pool:
        futures = {pool.submit(_one, job): i for i, job in enumerate(todo)}
        for fut in tqdm(as_completed(futures), total=len(futures), unit="run",
                        desc="compare", file=sys.stderr, disable=None):
            docs[futures[fut]] = fut.result()
    if args.out:
        Path(args.out).write_text(json.dumps(docs, indent=2) + "\n")
    if args.json:
        json.dump(docs, sys.stdout, indent=2)
        print()
        return 0
    print(f"rhmpc compare: {len(runs)} runs on robot {runs[0].robot}, {_lengths(runs)}, "
          f"error against the {runs[0].ground_truth} motion")
    print(comparison_table(docs, predictors, columns))
    if args.paper:
        from rhmpc.studies.paper import paper_table

        print()
        print(paper_table(docs, predictors, columns))
    failed = [d for d in docs if "error" in d]
    for d in failed:
        print(f"failed: {d['predictor']} on {d['scenario']} seed {d['seed']}: {d['error']}")
    return 1 if failed else 0


def _lengths(runs: list[RunConfig]) -> str:
    """``60 s each (metrics after 20 s)``, or each run's length where they differ."""
    spans = list(dict.fromkeys((c.loop.duration, c.loop.settling) for c in runs))
    if len(spans) == 1:
        return f"{spans[0][0]:g} s each (metrics after {spans[0][1]:g} s)"
    return "; ".join(f"{d:.4g} s (metrics after {s:.3g} s)" for d, s in spans)
