"""`rhmpc compare`: predictors × scenarios (or recordings) in parallel — the replica of Tuna et
al. Tables I–III, and the same table on the user's recordings (``--data``).

The command maps its options to the runs (:mod:`rhmpc.compare.jobs`), runs them
(:mod:`rhmpc.compare.runs`: the sweep runner of ``rhmpc tune``, local worker processes or a
dask.distributed cluster with ``--scheduler``) and prints their table (:mod:`rhmpc.compare.table`,
with ``--paper`` :mod:`rhmpc.paper`). A run lasts what ``rhmpc simulate`` runs (the loop's
defaults) unless told otherwise.

``--paper`` runs :data:`PAPER_SEEDS` seeds per cell unless ``--seeds`` says otherwise, and the
predictors of the published tables of the runs' setting.
"""

from __future__ import annotations

import argparse
import json
import sys

from rhmpc.cli import COMMANDS
from rhmpc.cli.options import (
    add_model_option,
    add_recording_options,
    add_run_options,
    add_split_option,
    parse_split,
    recording_options,
)
from rhmpc.cli.simulate import config_from_args
from rhmpc.compare.jobs import (
    DATA_PREDICTORS,
    TABLE_PREDICTORS,
    Job,
    check_predictors,
    data_columns,
    make_jobs,
    scenario_columns,
    setting_of,
)
from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig
from rhmpc.paper.tuna2013 import COLUMNS

#: Tuna et al. Table I/II column order (fixed rate: animals 1, 2; varying: 1, 3 top; 1, 3 side).
TABLE_SCENARIOS = COLUMNS
#: Seeds per cell of ``--paper`` (``--seeds`` overrides). Tuna et al. ran each cell ten times and
#: published the maximum (§VIII-B); a cell here is the mean and its 95 % interval, and a finding
#: is judged on intervals paired by seed. How many seeds decide the verdicts, and the time of
#: both presets' runs on two cores: docs/validation/tuna.md (``benchmarks/tuna_tables.py``).
PAPER_SEEDS = 4
#: Options that read a recording (``--data``); their ``argparse`` destinations.
READ_OPTIONS = ("var", "rows", "cols", "data_rate", "units", "topic", "frame")


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
    out.add_argument("--json", action="store_true", help="print the results as JSON (schema "
                     "rhmpc.compare/2: the runs, the cells with their 95%% intervals and, with "
                     "--paper, the published cells beside ours; the user guide's 'The JSON "
                     "documents')")
    out.add_argument("--csv", action="store_true", help="print the table's cells as CSV: one "
                     "line per column and predictor with the runs behind it, each metric's mean "
                     "and 95%% half-width, and the ratios")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.add_argument("--out", metavar="FILE.json", help="write the results as --json prints them")
    p.set_defaults(func=run)


def seeds_of(args: argparse.Namespace) -> list[int]:
    """The seeds of every cell: ``--seeds`` of them from ``--seed`` (default 1, and
    :data:`PAPER_SEEDS` with ``--paper``)."""
    count = args.seeds if args.seeds is not None else PAPER_SEEDS if args.paper else 1
    if count < 1 or (args.jobs is not None and args.jobs < 1):
        raise UsageError("--seeds and --jobs must be >= 1")
    return list(range(args.seed, args.seed + count))


def jobs(args: argparse.Namespace) -> list[Job]:
    """One :class:`~rhmpc.compare.jobs.Job` per predictor × column × seed, in the table's
    order."""
    seeds = seeds_of(args)
    columns = _data_columns(args) if args.data else _scenario_columns(args)
    base = _base_config(args)
    return make_jobs(base, columns, _predictors(args, base), seeds, args.model or ())


def _predictors(args: argparse.Namespace, base: RunConfig) -> list[str]:
    """--predictors, or the default rows: the published tables' with --paper."""
    from rhmpc.paper.tables import table_predictors

    if args.predictors:
        names = args.predictors.split(",")
    elif args.data:
        names = list(DATA_PREDICTORS)
    elif args.paper:
        names = list(table_predictors(setting_of([base])))
    else:
        names = list(TABLE_PREDICTORS)
    return check_predictors(names)


def _scenario_columns(args: argparse.Namespace) -> list:
    """(column, settings) of each scenario."""
    if args.points is not None or args.poi is not None or args.split is not None or any(
            getattr(args, k, None) is not None for k in READ_OPTIONS):
        raise UsageError("--points, --poi, --split, --var, --rows, --cols, --rate, --units, "
                         "--topic and --frame need --data FILE")
    names = args.scenarios or ",".join(TABLE_SCENARIOS)
    return scenario_columns(names.split(","), args.full)


def _data_columns(args: argparse.Namespace) -> list:
    """(column, settings) of each recording, or of each tracked point with --points."""
    if args.scenarios is not None or args.full or args.paper:
        raise UsageError("--scenarios, --full and --paper apply to scenarios, not --data")
    if args.poi is not None and args.points is not None:
        raise UsageError("give --poi N or --points, not both")
    split = parse_split(args.split)
    if split and (args.duration is not None or args.settling is not None):
        raise UsageError("--split TRAIN:END sets the settling and the duration: give neither "
                         "--settling nor --duration with it")
    points = args.points if args.poi is None else str(args.poi)
    return data_columns(args.data, recording_options(args), points, recorded=not args.sensor,
                        split=split, duration=args.duration, whole=not args.config)


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
    from rhmpc.compare.runs import Execution, document, footer, header, run_comparison
    from rhmpc.compare.table import json_ready
    from rhmpc.experiment.config import input_files
    from rhmpc.tuning.progress import note

    todo = jobs(args)
    if args.out:
        io.check_output(args.out, "--out", inputs=[
            *(f for job in todo for f in input_files(job.config)), *filter(None, [args.config])])
    text = not (args.json or args.csv)
    intro = header(todo, bool(args.data), len(seeds_of(args)))
    print(intro, flush=True) if text else note(intro, args.quiet)
    how = Execution(args.jobs, args.scheduler, parse_split(args.split), tuple(args.model or ()),
                    args.quiet)
    comparison = run_comparison(todo, how)
    results = document(comparison, seeds_of(args))
    if args.paper and comparison.done:
        from rhmpc.paper.tables import paper_document

        results["paper"] = paper_document(comparison.docs, *comparison.axes(done=True),
                                          setting=comparison.setting(done=True))
    results = json_ready(results)
    if args.out:
        io.write_text(args.out, json.dumps(results, indent=2) + "\n")
    _print_results(results, comparison, args)
    note(footer(comparison), args.quiet)
    if comparison.interrupted:
        print(f"rhmpc compare: interrupted with {len(comparison.done)} of {len(todo)} runs "
              "done; the tables above hold those", file=sys.stderr)
        return 130
    failed = [d for d in comparison.docs if "error" in d]
    for d in failed:
        print(f"rhmpc compare: failed: {d['predictor']} on {d['scenario']} seed {d['seed']}: "
              f"{d['error']}", file=sys.stderr)
    return 1 if failed else 0


def _print_results(results: dict, comparison, args: argparse.Namespace) -> None:
    """The JSON document, the CSV cells, or the tables (each printed as soon as it is made)."""
    from rhmpc.compare.table import comparison_csv, comparison_table

    predictors, columns = comparison.axes()
    docs, recordings = comparison.docs, bool(args.data)
    if args.json:
        json.dump(results, sys.stdout, indent=2)
        print()
        return
    if args.csv:
        sys.stdout.write(comparison_csv(docs, predictors, columns, recordings))
        return
    print(comparison_table(docs, predictors, columns, recordings, seeds_of(args)), flush=True)
    if args.paper:
        from rhmpc.paper.tables import paper_table

        print()
        print(paper_table(docs, predictors, columns, setting=comparison.setting()), flush=True)
    if results.get("loop_gap"):
        from rhmpc.compare.loop_gap import gap_table

        print("\n".join(gap_table(results["loop_gap"])), flush=True)
