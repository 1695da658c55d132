"""`rhmpc compare`: predictors × scenarios (or recordings) in parallel — the replica of Tuna et
al. Tables I/III, and the same table on the user's recordings (``--data``)."""

from __future__ import annotations

import argparse
import json
import os
import sys
from concurrent.futures import FIRST_COMPLETED, Future, wait
from dataclasses import dataclass

from rhmpc.cli import COMMANDS
from rhmpc.cli.simulate import (
    add_recording_options,
    add_run_options,
    config_from_args,
    recording_options,
)
from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.studies.paper import COLUMNS
from sim.recordings.shipped import resolve_all

#: Tuna et al. Table I/II column order (fixed rate: animals 1, 2; varying: 1, 3 top; 1, 3 side).
TABLE_SCENARIOS = COLUMNS
TABLE_PREDICTORS = ("exact", "one-step", "generalized", "ekf")
#: The predictors on recordings: ``hold`` first, the ratios' yardstick there.
DATA_PREDICTORS = ("hold", "exact", "one-step", "generalized", "ekf")
#: Seconds between two looks at the runs in flight (the progress bar's redraws).
POLL_S = 0.5
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
        "compare", help=COMMANDS["compare"],
        description="Run every predictor on every scenario (or recording, --data) in closed "
        "loop (parallel processes) and print RMS (max) position error and RMS control effort "
        "per predictor and column, with the ratio to the 'exact' row on scenarios and to the "
        "'hold' row on recordings (where 'exact' reads the recorded future). Progress goes to "
        "stderr, the tables to stdout as soon as the runs are done.")
    p.add_argument("--predictors",
                   help=f"comma-separated predictor names (default {','.join(TABLE_PREDICTORS)}; "
                   f"with --data {','.join(DATA_PREDICTORS)})")
    p.add_argument("--scenarios",
                   help="comma-separated scenario names (default: the six Table-I replicas)")
    p.add_argument("--data", nargs="+", metavar="FILE", help="recordings instead of scenarios, "
                   "one column each (CSV t,x,y,z in s and mm, NPZ, MATLAB .mat); each runs "
                   "whole unless --duration, with the sensor 'recorded' unless --sensor")
    p.add_argument("--points", metavar="all|N[,N...]", help="files of several tracked points "
                   "(CSV t,x1,y1,z1,x2,...; NPZ (n, P, 3); MAT 3P x n): one column per point "
                   "(all) or per chosen point, numbered from 1")
    p.add_argument("--poi", type=int, metavar="N", help="with --data: only point N (numbered "
                   "from 1) of files of several tracked points, the others given to the "
                   "predictors that read them (the same as --points N)")
    p.add_argument("--seeds", type=int, default=1,
                   help="runs per cell, seeds SEED..SEED+S-1 (default 1); with 2 or more, each "
                   "cell is the mean and the 95%% interval of the mean (Student t)")
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
    out = p.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true", help="print all result documents as JSON: "
                     "one per column, predictor and seed, each with scenario (the column: a "
                     "scenario, a file name, FILE:pN for a point), rms_error_mm, max_error_mm "
                     "and rms_effort_mNm (a failed run: error)")
    out.add_argument("--csv", action="store_true", help="print the table's cells as CSV: one "
                     "line per column and predictor with the runs behind it, each metric's mean "
                     "and 95%% half-width, and the ratios")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.add_argument("--out", metavar="FILE.json", help="write all result documents")
    p.set_defaults(func=run)


def run_job(job: Job) -> dict:
    """Run one job (in a worker): its document, or a failed one with ``error``."""
    config = job.config
    try:
        doc = run_experiment(config)[1]
    except Exception as exc:  # one failed cell must not lose the others
        doc = failed_doc(job, f"{type(exc).__name__}: {exc}")
    return _labelled(doc, job)


def failed_doc(job: Job, error: str) -> dict:
    """The document of a run that failed: its predictor, seed, settings and ``error``."""
    from rhmpc.experiment.run import jsonable

    config = job.config
    return {"predictor": config.predictor, "seed": config.seed, "error": error,
            "settings": jsonable(config.to_dict())}


def _labelled(doc: dict, job: Job) -> dict:
    doc["scenario"] = job.column
    if job.config.data is not None:
        doc["data"] = job.config.data
        doc["point"] = job.config.data_read.get("point")
    return doc


def configs(args: argparse.Namespace) -> list[RunConfig]:
    """One run configuration per predictor × scenario (or recording) × seed."""
    return [job.config for job in jobs(args)]


def jobs(args: argparse.Namespace) -> list[Job]:
    """One :class:`Job` per predictor × column × seed, in the table's order."""
    from predictors import PREDICTORS

    names = args.predictors or ",".join(DATA_PREDICTORS if args.data else TABLE_PREDICTORS)
    predictors = list(dict.fromkeys(p.strip() for p in names.split(",") if p.strip()))
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

    if args.points is not None or args.poi is not None or any(
            getattr(args, k, None) is not None for k in READ_OPTIONS):
        raise UsageError("--points, --poi, --var, --rows, --cols, --rate and --units need "
                         "--data FILE")
    names = args.scenarios or ",".join(TABLE_SCENARIOS)
    scenarios = [s.strip() for s in names.split(",") if s.strip()]
    unknown = [s for s in scenarios if s not in SCENARIOS]
    if unknown:
        raise UsageError(f"unknown scenario(s) {', '.join(unknown)}; valid: {', '.join(SCENARIOS)}")
    return [(s, {"scenario": s, **({"loop.duration": SPECS[s].duration} if args.full else {})})
            for s in scenarios]


def _data_columns(args: argparse.Namespace) -> list[tuple[str, dict]]:
    """(column, settings) of each recording, or of each tracked point with --points."""
    from rhmpc.studies.tracks import file_points, parse_points

    if args.scenarios is not None or args.full or args.paper:
        raise UsageError("--scenarios, --full and --paper apply to scenarios, not --data")
    try:
        data, read, poi = resolve_all(args.data, recording_options(args))
        if args.poi is not None and args.points is not None:
            raise UsageError("give --poi N or --points, not both")
        if args.points is None and (args.poi or poi) is not None:
            args.points = str(args.poi or poi)
        files = file_points(data, parse_points(args.points), read)
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
    import boundary
    from rhmpc.experiment.config import input_files
    from rhmpc.tuning.progress import note

    todo = jobs(args)
    if args.out:
        boundary.check_output(args.out, "--out", inputs=[
            *(f for job in todo for f in input_files(job.config)), *filter(None, [args.config])])
    runs = [job.config for job in todo]
    text = not (args.json or args.csv)
    if text:
        print(_header(todo, args), flush=True)
    else:
        note(_header(todo, args), args.quiet)
    docs, wall = execute(todo, min(args.jobs, len(todo)), args.quiet)
    if args.out:
        boundary.write_text(args.out, json.dumps(docs, indent=2) + "\n")
    _print_results(docs, todo, args)
    note(_footer(docs, runs, wall, min(args.jobs, len(todo))), args.quiet)
    failed = [d for d in docs if "error" in d]
    for d in failed:
        print(f"rhmpc compare: failed: {d['predictor']} on {d['scenario']} seed {d['seed']}: "
              f"{d['error']}", file=sys.stderr)
    return 1 if failed else 0


def _print_results(docs: list[dict], todo: list[Job], args: argparse.Namespace) -> None:
    """The JSON documents, the CSV cells, or the tables (each printed as soon as it is made)."""
    from rhmpc.studies.comparison import comparison_csv, comparison_table

    predictors = list(dict.fromkeys(job.config.predictor for job in todo))
    columns = list(dict.fromkeys(job.column for job in todo))
    recordings = bool(args.data)
    if args.json:
        json.dump(docs, sys.stdout, indent=2)
        print()
        return
    if args.csv:
        sys.stdout.write(comparison_csv(docs, predictors, columns, recordings))
        return
    seeds = list(range(args.seed, args.seed + args.seeds))
    print(comparison_table(docs, predictors, columns, recordings, seeds), flush=True)
    if args.paper:
        from rhmpc.studies.paper import paper_table

        print()
        print(paper_table(docs, predictors, columns, setting=_setting(todo)), flush=True)


def _setting(todo: list[Job]) -> str:
    """Tuna's setting of the runs as configured: ``hardware`` for the hardware-like plant."""
    models = {job.config.plant.model for job in todo}
    return "hardware" if models == {"hardware"} else "simulation"


def execute(todo: list[Job], processes: int, quiet: bool = False) -> tuple[list[dict], float]:
    """Run the jobs in ``processes`` worker processes, with a progress bar on stderr.

    Each worker runs :func:`run_job` (looked up when called, so that a test may stand in for
    it) and dies with this process. Ctrl-C stops the workers at once.

    Returns
    -------
    tuple[list[dict], float]
        The documents in the jobs' order (a run that failed or whose worker died has
        ``error``), and the wall time [s].
    """
    import time

    from rhmpc.tuning.progress import Heartbeat, note, progress_bar
    from rhmpc.tuning.workers import process_pool, stop_executor

    note(f"rhmpc compare: running {len(todo)} run(s) on {processes} process(es)", quiet)
    start = time.perf_counter()
    docs: list[dict] = [{} for _ in todo]
    pool = process_pool(processes, start_method="fork")  # the parent has the run stack loaded
    futures = {pool.submit(run_job, job): i for i, job in enumerate(todo)}
    bar = progress_bar(len(todo), "run", "compare", quiet)
    beat, failed = Heartbeat(bar), 0
    try:
        waiting: set[Future] = set(futures)
        while waiting:
            done, waiting = wait(waiting, timeout=POLL_S, return_when=FIRST_COMPLETED)
            for fut in done:
                i = futures[fut]
                docs[i] = _outcome(fut, todo[i])
                failed += "error" in docs[i]
                bar.update(1)
                if failed:
                    bar.set_postfix(failed=failed)
            beat()
    except KeyboardInterrupt:
        bar.close()
        stop_executor(pool, futures)
        raise
    bar.close()
    pool.shutdown()
    return docs, time.perf_counter() - start


def _outcome(fut: Future, job: Job) -> dict:
    """A finished future's document; a worker that died gives a failed one."""
    try:
        return fut.result()
    except Exception as exc:  # BrokenProcessPool: the worker died (a crash in C code)
        return _labelled(failed_doc(job, f"worker died ({type(exc).__name__}: {exc})"), job)


def _header(todo: list[Job], args: argparse.Namespace) -> str:
    """What runs: how many, of what, on which robot, how long, scored against what."""
    runs = [job.config for job in todo]
    n_pred = len({c.predictor for c in runs})
    n_col = len({job.column for job in todo})
    what = "recording" if args.data else "scenario"
    return (f"rhmpc compare: {len(runs)} runs ({n_pred} predictor{'s' * (n_pred != 1)} × "
            f"{n_col} {what}{'s' * (n_col != 1)} × {args.seeds} seed{'s' * (args.seeds != 1)}) "
            f"on robot {runs[0].robot}\n  {_lengths(runs)}, error against the "
            f"{runs[0].ground_truth} motion")


def _footer(docs: list[dict], runs: list[RunConfig], wall: float, processes: int) -> str:
    """``4 runs in 12 s on 2 processes; each run 3.4× faster than real time``."""
    from rhmpc.tuning.progress import format_duration, speed_phrase

    ok = [(d, c) for d, c in zip(docs, runs, strict=True) if "error" not in d]
    simulated = sum(c.loop.duration for _, c in ok)
    run_wall = sum(float(d.get("wall_s", 0.0)) for d, _ in ok)
    line = f"rhmpc compare: {len(runs)} runs in {format_duration(wall)} on {processes} process(es)"
    if simulated > 0 and run_wall > 0:
        line += f"; each run {speed_phrase(simulated, run_wall)}"
    return line


def _lengths(runs: list[RunConfig]) -> str:
    """``60 s each (metrics after 20 s)``, or each run's length where they differ."""
    from rhmpc.tuning.progress import format_duration

    spans = list(dict.fromkeys((c.loop.duration, c.loop.settling) for c in runs))
    if len(spans) == 1:
        return (f"{format_duration(spans[0][0])} each (metrics after "
                f"{format_duration(spans[0][1])})")
    return "; ".join(f"{format_duration(d)} (metrics after {format_duration(s)})"
                     for d, s in spans)
