"""`rhmpc compare`: predictors × scenarios (or recordings) in parallel — the replica of Tuna et
al. Tables I–III, and the same table on the user's recordings (``--data``).

The runs go through the sweep runner of ``rhmpc tune`` (:func:`rhmpc.tuning.runner.run_sweep`):
local worker processes, or a dask.distributed cluster with ``--scheduler``. A run lasts what
``rhmpc simulate`` runs (the loop's defaults) unless told otherwise.

``--paper`` runs :data:`PAPER_SEEDS` seeds per cell unless ``--seeds`` says otherwise, and the
predictors of the published tables of the runs' setting.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from rhmpc.cli import COMMANDS
from rhmpc.cli.simulate import (
    add_model_option,
    add_recording_options,
    add_run_options,
    add_split_option,
    config_from_args,
    parse_split,
    recording_options,
)
from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.experiment.config import with_split
from rhmpc.experiment.fitting import with_models
from rhmpc.sim.recordings.shipped import resolve_all
from rhmpc.studies.tuna2013 import COLUMNS

#: Tuna et al. Table I/II column order (fixed rate: animals 1, 2; varying: 1, 3 top; 1, 3 side).
TABLE_SCENARIOS = COLUMNS
TABLE_PREDICTORS = ("exact", "one-step", "generalized", "ekf")
#: The predictors on recordings: ``hold`` first, the ratios' yardstick there.
DATA_PREDICTORS = ("hold", "exact", "one-step", "generalized", "ekf")
#: Seeds per cell of ``--paper`` (``--seeds`` overrides). Tuna et al. ran each cell ten times and
#: published the maximum (§VIII-B); a cell here is the mean and its 95 % interval, and a finding
#: is judged on intervals paired by seed. How many seeds decide the verdicts, and the time of
#: both presets' runs on two cores: docs/validation/tuna.md (``benchmarks/tuna_tables.py``).
PAPER_SEEDS = 4
#: Options that read a recording (``--data``); their ``argparse`` destinations.
READ_OPTIONS = ("var", "rows", "cols", "data_rate", "units", "topic", "frame")


@dataclass(frozen=True)
class Job:
    """One closed-loop run of the table.

    Attributes
    ----------
    key : str
        Its place in the table's order (unique among the jobs).
    column : str
        The table's column: a scenario, a recording (its file name), or one tracked point of
        it (``rec.mat:p2``).
    config : RunConfig
        The run's settings.
    """

    key: str
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
                   "with --paper the published tables' rows; with --data "
                   f"{','.join(DATA_PREDICTORS)})")
    p.add_argument("--scenarios",
                   help="comma-separated scenario names (default: the six Table-I replicas)")
    p.add_argument("--data", nargs="+", metavar="FILE", help="recordings instead of scenarios, "
                   "one column each (CSV t,x,y,z in s and mm, NPZ, MATLAB .mat, a ROS bag "
                   "with --topic); each runs "
                   "whole unless --duration, with the sensor 'recorded' unless --sensor")
    p.add_argument("--points", metavar="all|N[,N...]", help="files of several tracked points "
                   "(CSV t,x1,y1,z1,x2,...; NPZ (n, P, 3); MAT 3P x n): one column per point "
                   "(all) or per chosen point, numbered from 1")
    p.add_argument("--poi", type=int, metavar="N", help="with --data: only point N (numbered "
                   "from 1) of files of several tracked points, the others given to the "
                   "predictors that read them (the same as --points N)")
    p.add_argument("--seeds", type=int,
                   help=f"runs per cell, seeds SEED..SEED+S-1 (default 1; {PAPER_SEEDS} with "
                   "--paper); with 2 or more, each cell is the mean and the 95%% interval of "
                   "the mean (Student t)")
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument("--paper", action="store_true",
                   help="also print Tuna et al. 2013's tables of the runs' setting beside ours "
                   "(Table I for a simulated plant, Tables II-III for the hardware plant): "
                   "paper, ours and their ratio for every cell, and each published finding "
                   "reproduced, not reproduced or undecided, with its measured cause; runs "
                   f"the tables' predictors on {PAPER_SEEDS} seeds unless told otherwise")
    p.add_argument("--jobs", type=int,
                   help="parallel processes (default: the number of cores; with --scheduler, "
                   "runs in flight, default the cluster's threads)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on a dask.distributed cluster (e.g. tcp://host:8786) instead of "
                   "local processes, as rhmpc tune does; needs the 'dask' extra here and on "
                   "the workers")
    p.add_argument("--full", action="store_true",
                   help="use each scenario's full duration (235-472 s) instead of --duration")
    add_run_options(p)
    add_recording_options(p)
    add_split_option(p, "; each predictor's closed loop is set beside its open-loop forecast "
                     "of the same samples, one sample ahead")
    add_model_option(p)
    out = p.add_mutually_exclusive_group()
    out.add_argument("--json", action="store_true", help="print the results as JSON: runs (one "
                     "document per column, predictor and seed, each with scenario (the column: "
                     "a scenario, a file name, FILE:pN for a point), rms_error_mm, max_error_mm "
                     "and rms_effort_mNm; a failed run: error), cells (per predictor and "
                     "column: runs, and each metric's mean and ci95 = [low, high] of its 95%% "
                     "interval) and, with --paper, paper (the published cells beside ours and "
                     "the findings, each with its verdict and cause)")
    out.add_argument("--csv", action="store_true", help="print the table's cells as CSV: one "
                     "line per column and predictor with the runs behind it, each metric's mean "
                     "and 95%% half-width, and the ratios")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.add_argument("--out", metavar="FILE.json", help="write the results as --json prints them")
    p.set_defaults(func=run)


def run_job(job: Job) -> dict:
    """Run one job (in a worker): its document, or a failed one with ``error``."""
    config = job.config
    try:
        doc = run_experiment(config)[1]
    except Exception as exc:  # one failed cell must not lose the others
        doc = failed_doc(job, f"{type(exc).__name__}: {exc}")
    return _labelled(doc, job)


def evaluate_job(job: Job, extra: dict | None = None) -> dict:
    """The sweep runner's evaluation: :func:`run_job` (looked up when called, so that a test
    may stand in for it), one at a time per process, as ``rhmpc tune``'s evaluations."""
    from rhmpc.tuning.evaluate import RUN_LOCK

    with RUN_LOCK:
        return run_job(job)


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


def seeds_of(args: argparse.Namespace) -> list[int]:
    """The seeds of every cell: ``--seeds`` of them from ``--seed`` (default 1, and
    :data:`PAPER_SEEDS` with ``--paper``)."""
    count = args.seeds if args.seeds is not None else PAPER_SEEDS if args.paper else 1
    if count < 1 or (args.jobs is not None and args.jobs < 1):
        raise UsageError("--seeds and --jobs must be >= 1")
    return list(range(args.seed, args.seed + count))


def setting_of_config(config: RunConfig) -> str:
    """Tuna's setting of a run: ``hardware`` for the hardware-like plant, else ``simulation``."""
    return "hardware" if config.plant.model == "hardware" else "simulation"


def _predictors(args: argparse.Namespace, base: RunConfig) -> list[str]:
    """--predictors, or the default rows: the published tables' with --paper."""
    from rhmpc.predictors import predictor_names
    from rhmpc.studies.paper import table_predictors

    if args.predictors:
        names = args.predictors.split(",")
    elif args.data:
        names = list(DATA_PREDICTORS)
    elif args.paper:
        names = list(table_predictors(setting_of_config(base)))
    else:
        names = list(TABLE_PREDICTORS)
    predictors = list(dict.fromkeys(p.strip() for p in names if p.strip()))
    bad = [p for p in predictors if p not in predictor_names()]
    if bad:
        raise UsageError(f"unknown predictor(s) {', '.join(bad)}; valid: "
                         f"{', '.join(predictor_names())}")
    return predictors


def jobs(args: argparse.Namespace) -> list[Job]:
    """One :class:`Job` per predictor × column × seed, in the table's order."""
    seeds = seeds_of(args)
    columns = _data_columns(args) if args.data else _scenario_columns(args)
    base = _base_config(args)
    predictors = _predictors(args, base)
    out = []
    for column, changes in columns:
        run_base = base.replace(**changes)
        for predictor in predictors:
            for seed in seeds:
                config = run_base.replace(predictor=predictor, seed=seed)
                out.append(Job(str(len(out)), column,
                               with_models(config, args.model or (), strict=False)))
    return out


def _scenario_columns(args: argparse.Namespace) -> list[tuple[str, dict]]:
    """(column, settings) of each scenario."""
    from rhmpc.sim.heart import SCENARIOS, SPECS

    if args.points is not None or args.poi is not None or args.split is not None or any(
            getattr(args, k, None) is not None for k in READ_OPTIONS):
        raise UsageError("--points, --poi, --split, --var, --rows, --cols, --rate, --units, "
                         "--topic and --frame need --data FILE")
    names = args.scenarios or ",".join(TABLE_SCENARIOS)
    scenarios = list(dict.fromkeys(s.strip() for s in names.split(",") if s.strip()))
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
    split = parse_split(args.split)
    if split and (args.duration is not None or args.settling is not None):
        raise UsageError("--split TRAIN:END sets the settling and the duration: give neither "
                         "--settling nor --duration with it")
    out = []
    for group in files:
        for column, path, point, recording in group:
            changes = {"data": path, "data_read": {**read, **({"point": point} if point else {})},
                       **sensor}
            if split:
                span = with_split(RunConfig(data=path, data_read=changes["data_read"]), split).loop
                changes.update({"loop.settling": span.settling, "loop.duration": span.duration})
            elif args.duration is None and not args.config:  # default: the whole recording
                changes["loop.duration"] = recording.duration
            elif args.duration is not None and args.duration > recording.duration:
                raise UsageError(f"{path}: the recording lasts {recording.duration:.2f} s, "
                                 f"--duration asks for {args.duration:.2f} s")
            out.append((column, changes))
    return out


def _base_config(args: argparse.Namespace) -> RunConfig:
    """The settings every run shares, as ``simulate`` makes them: defaults < --config <
    --preset < options < --set (the column, the predictor and the seed come per run)."""
    saved = {k: getattr(args, k, None) for k in ("predictor", "scenario", "data", "seed",
                                                 "split", "poi", "model", *READ_OPTIONS)}
    for key in saved:
        setattr(args, key, None)
    try:
        return config_from_args(args)
    finally:
        for key, value in saved.items():
            setattr(args, key, value)


def run(args: argparse.Namespace) -> int:
    from rhmpc import io
    from rhmpc.experiment.config import input_files
    from rhmpc.tuning.progress import note

    todo = jobs(args)
    if args.out:
        io.check_output(args.out, "--out", inputs=[
            *(f for job in todo for f in input_files(job.config)), *filter(None, [args.config])])
    text = not (args.json or args.csv)
    if text:
        print(_header(todo, args), flush=True)
    else:
        note(_header(todo, args), args.quiet)
    with tempfile.TemporaryDirectory(prefix="rhmpc-models-") as folder:
        beside, todo = open_loops(todo, args, Path(folder)) if args.split else ({}, todo)
        outcome, where = execute(todo, args)
    done = [job for job in todo if job.key in outcome.by_key]
    docs = [outcome.by_key[job.key] for job in done]
    results = _document(docs, done, args, outcome.interrupted)
    if args.split:
        from rhmpc.studies.loop_gap import gap_rows

        results["loop_gap"] = gap_rows(docs, beside)
    if args.out:
        io.write_text(args.out, json.dumps(results, indent=2) + "\n")
    _print_results(results, docs, todo, args)
    note(_footer(docs, [job.config for job in done], outcome.elapsed_s, where), args.quiet)
    if outcome.interrupted:
        print(f"rhmpc compare: interrupted with {len(done)} of {len(todo)} runs done; the "
              "tables above hold those", file=sys.stderr)
        return 130
    failed = [d for d in docs if "error" in d]
    for d in failed:
        print(f"rhmpc compare: failed: {d['predictor']} on {d['scenario']} seed {d['seed']}: "
              f"{d['error']}", file=sys.stderr)
    return 1 if failed else 0


def _document(docs: list[dict], done: list[Job], args: argparse.Namespace,
              interrupted: bool) -> dict:
    """What ``--json`` prints and ``--out`` writes: the runs, the cells and, with --paper, the
    published tables beside ours and the findings."""
    from rhmpc.studies.comparison import cells_document, json_ready

    predictors = list(dict.fromkeys(job.config.predictor for job in done))
    columns = list(dict.fromkeys(job.column for job in done))
    out = {"runs": docs, "seeds": seeds_of(args), "interrupted": interrupted,
           "cells": cells_document(docs, predictors, columns)}
    if args.paper and done:
        from rhmpc.studies.paper import paper_document

        out["paper"] = paper_document(docs, predictors, columns, setting=_setting(done))
    return json_ready(out)


def _print_results(results: dict, docs: list[dict], todo: list[Job],
                   args: argparse.Namespace) -> None:
    """The JSON document, the CSV cells, or the tables (each printed as soon as it is made)."""
    from rhmpc.studies.comparison import comparison_csv, comparison_table

    predictors = list(dict.fromkeys(job.config.predictor for job in todo))
    columns = list(dict.fromkeys(job.column for job in todo))
    recordings = bool(args.data)
    if args.json:
        json.dump(results, sys.stdout, indent=2)
        print()
        return
    if args.csv:
        sys.stdout.write(comparison_csv(docs, predictors, columns, recordings))
        return
    print(comparison_table(docs, predictors, columns, recordings, seeds_of(args)), flush=True)
    if args.paper:
        from rhmpc.studies.paper import paper_table

        print()
        print(paper_table(docs, predictors, columns, setting=_setting(todo)), flush=True)
    if results.get("loop_gap"):
        from rhmpc.studies.loop_gap import gap_table

        print("\n".join(gap_table(results["loop_gap"])), flush=True)


def open_loops(todo: list[Job], args: argparse.Namespace,
               folder: Path) -> tuple[dict[str, dict], list[Job]]:
    """Per recording column of a split: every predictor's open-loop forecast of the scored
    samples one sample ahead (:func:`rhmpc.studies.loop_gap.open_loop_beside`), made here
    before the closed loops run; and the jobs, whose predictors fitted before the run load
    the models fitted there (saved in ``folder``) instead of fitting again (fit once, run
    many), unless ``--model`` names others or the runs go to a cluster."""
    from rhmpc.studies.loop_gap import open_loop_beside
    from rhmpc.tuning.progress import note

    out, share, split = {}, not (args.model or args.scheduler), parse_split(args.split)
    for i, column in enumerate(dict.fromkeys(job.column for job in todo)):
        config = next(job.config for job in todo if job.column == column)
        names = list(dict.fromkeys(job.config.predictor for job in todo if job.column == column))
        note(f"rhmpc compare: the open loop on {column}, split {split[0]}:{split[1]}",
             args.quiet)
        save = folder / str(i) if share else None
        if save is not None:
            save.mkdir()
        try:
            out[column] = open_loop_beside(
                config.data, config.data_read, split, names,
                config.reference.prediction_points, config.seed,
                None if args.quiet else (lambda text: note(f"  {text}", False)), save)
        except ValueError as exc:
            raise UsageError(f"{column}: {exc}") from None
        if save is not None:
            files = sorted(save.iterdir())
            todo = [Job(j.key, j.column, with_models(j.config, files, strict=False))
                    if j.column == column else j for j in todo]
    return out, todo


def _setting(todo: list[Job]) -> str:
    """Tuna's setting of the runs as configured: ``hardware`` for the hardware-like plant."""
    settings = {setting_of_config(job.config) for job in todo}
    return "hardware" if settings == {"hardware"} else "simulation"


def execute(todo: list[Job], args: argparse.Namespace):
    """Run the jobs through the sweep runner, with a progress bar on stderr.

    Local worker processes are forked (the parent has the run stack loaded), or started afresh
    where the open loops of a split may have run PyTorch here (a fork does not carry its
    threads: the workers hung), and die with this process; ``--scheduler`` sends the jobs to a
    Dask cluster. Ctrl-C stops the workers at once and keeps the runs that finished.

    Returns
    -------
    tuple[SweepOutcome, str]
        The outcome (documents by job key; a run that failed or whose worker died twice has
        ``error``; ``interrupted``) and where the runs ran, in words.
    """
    from rhmpc.tuning.progress import Heartbeat, note, progress_bar
    from rhmpc.tuning.runner import executors, run_sweep

    fitted_here = args.split and "torch" in sys.modules  # the open loops ran PyTorch
    backend = executors(args.jobs, args.scheduler, len(todo),
                        start_method="spawn" if fitted_here else "fork")
    note(f"rhmpc compare: running {len(todo)} run(s) on {backend.where}", args.quiet)
    bar = progress_bar(len(todo), "run", "compare", args.quiet)
    failed = 0

    def on_result(doc: dict) -> None:
        nonlocal failed
        failed += "error" in doc
        bar.update(1)
        if failed:
            bar.set_postfix(failed=failed)

    def failed_run(job: Job, error: str) -> dict:
        return _labelled(failed_doc(job, error), job)

    try:
        outcome = run_sweep(todo, None, backend.factory, backend.window, evaluate=evaluate_job,
                            on_result=on_result, heartbeat=Heartbeat(bar), failed=failed_run)
    finally:
        bar.close()
        backend.close()
    return outcome, backend.where


def _header(todo: list[Job], args: argparse.Namespace) -> str:
    """What runs: how many, of what, on which robot, how long, scored against what."""
    runs = [job.config for job in todo]
    n_pred = len({c.predictor for c in runs})
    n_col = len({job.column for job in todo})
    what = "recording" if args.data else "scenario"
    n_seeds = len(seeds_of(args))
    return (f"rhmpc compare: {len(runs)} runs ({n_pred} predictor{'s' * (n_pred != 1)} × "
            f"{n_col} {what}{'s' * (n_col != 1)} × {n_seeds} seed{'s' * (n_seeds != 1)}) "
            f"on robot {runs[0].robot}\n  {_lengths(runs)}, error against the "
            f"{runs[0].ground_truth} motion")


def _footer(docs: list[dict], runs: list[RunConfig], wall: float, where: str) -> str:
    """``4 runs in 12 s on 2 local process(es); each run 3.4× faster than real time``."""
    from rhmpc.tuning.progress import format_duration, speed_phrase

    ok = [(d, c) for d, c in zip(docs, runs, strict=True) if "error" not in d]
    simulated = sum(c.loop.duration for _, c in ok)
    run_wall = sum(float(d.get("wall_s", 0.0)) for d, _ in ok)
    line = f"rhmpc compare: {len(runs)} runs in {format_duration(wall)} on {where}"
    if simulated > 0 and run_wall > 0:
        line += f"; each run {speed_phrase(simulated, run_wall)}"
    return line


def _lengths(runs: list[RunConfig]) -> str:
    """``60 s each (metrics after 20 s)``, or each run's length where they differ."""
    from rhmpc.tuning.progress import format_duration

    spans = list(dict.fromkeys((c.loop.duration, c.loop.settling_s) for c in runs))
    if len(spans) == 1:
        return (f"{format_duration(spans[0][0])} each (metrics after "
                f"{format_duration(spans[0][1])})")
    return "; ".join(f"{format_duration(d)} (metrics after {format_duration(s)})"
                     for d, s in spans)
