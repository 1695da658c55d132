"""`rhmpc compare`: predictors × scenarios in parallel — the replica of Tuna et al. Tables I/III."""

from __future__ import annotations

import argparse
import json
import os
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from rhmpc.cli.simulate import add_run_options, config_from_args
from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.studies.paper import COLUMNS

#: Tuna et al. Table I/II column order (fixed rate: animals 1, 2; varying: 1, 3 top; 1, 3 side).
TABLE_SCENARIOS = COLUMNS
TABLE_PREDICTORS = ("exact", "one-step", "generalized", "ekf")
DEFAULT_DURATION = 60.0
DEFAULT_SETTLING = 20.0


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compare", help="predictors x scenarios in parallel: the Tuna Tables I/III replica",
        description="Run every predictor on every scenario in closed loop (parallel processes) "
        "and print RMS (max) position error and RMS control effort per predictor and scenario, "
        "with the ratio to the 'exact' row.")
    p.add_argument("--predictors", default=",".join(TABLE_PREDICTORS),
                   help="comma-separated predictor names (default %(default)s)")
    p.add_argument("--scenarios", default=",".join(TABLE_SCENARIOS),
                   help="comma-separated scenario names (default: the six Table-I replicas)")
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
    p.add_argument("--json", action="store_true", help="print all result documents as JSON: "
                   "one per scenario, predictor and seed, each with rms_error_mm, max_error_mm "
                   "and rms_effort_mNm")
    p.add_argument("--out", metavar="FILE.json", help="write all result documents")
    p.set_defaults(func=run)


def _one(config: RunConfig) -> dict:
    try:
        return run_experiment(config)[1]
    except Exception as exc:  # one failed cell must not lose the others
        return {"predictor": config.predictor, "scenario": config.scenario, "seed": config.seed,
                "error": f"{type(exc).__name__}: {exc}"}


def configs(args: argparse.Namespace) -> list[RunConfig]:
    """One run configuration per predictor × scenario × seed."""
    from sim.heart import SCENARIOS, SPECS

    predictors = [p.strip() for p in args.predictors.split(",") if p.strip()]
    scenarios = [s.strip() for s in args.scenarios.split(",") if s.strip()]
    unknown = [s for s in scenarios if s not in SCENARIOS]
    if unknown:
        raise UsageError(f"unknown scenario(s) {', '.join(unknown)}; valid: {', '.join(SCENARIOS)}")
    from predictors import PREDICTORS

    bad = [p for p in predictors if p not in PREDICTORS]
    if bad:
        raise UsageError(f"unknown predictor(s) {', '.join(bad)}; valid: {', '.join(PREDICTORS)}")
    if args.seeds < 1 or args.jobs < 1:
        raise UsageError("--seeds and --jobs must be >= 1")
    first_seed = args.seed
    args.predictor = args.scenario = args.data = args.seed = None
    duration, settling = args.duration, args.settling
    args.duration = args.settling = None
    base = config_from_args(args)
    if not args.config:
        base = base.replace(**{"loop.duration": DEFAULT_DURATION,
                               "loop.settling": DEFAULT_SETTLING})
    if duration is not None:
        base = base.replace(**{"loop.duration": duration,
                               "loop.settling": settling if settling is not None
                               else min(DEFAULT_SETTLING, duration / 3)})
    elif settling is not None:
        base = base.replace(**{"loop.settling": settling})
    out = []
    for scenario in scenarios:
        run_base = base.replace(scenario=scenario)
        if args.full:
            run_base = run_base.replace(**{"loop.duration": SPECS[scenario].duration})
        for predictor in predictors:
            for seed in range(first_seed, first_seed + args.seeds):
                out.append(run_base.replace(predictor=predictor, seed=seed))
    return out


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from rhmpc.studies.comparison import comparison_table

    runs = configs(args)
    predictors = list(dict.fromkeys(c.predictor for c in runs))
    scenarios = list(dict.fromkeys(c.scenario for c in runs))
    docs: list[dict] = []
    with ProcessPoolExecutor(max_workers=min(args.jobs, len(runs))) as pool:
        futures = [pool.submit(_one, c) for c in runs]
        for fut in tqdm(as_completed(futures), total=len(futures), unit="run",
                        desc="compare", file=sys.stderr, disable=None):
            docs.append(fut.result())
    order = {(c.predictor, c.scenario, c.seed): i for i, c in enumerate(runs)}
    docs.sort(key=lambda d: order.get((d["predictor"], d["scenario"], d["seed"]), 0))
    if args.out:
        Path(args.out).write_text(json.dumps(docs, indent=2) + "\n")
    if args.json:
        json.dump(docs, sys.stdout, indent=2)
        print()
        return 0
    s = runs[0].loop
    print(f"rhmpc compare: {len(runs)} runs on robot {runs[0].robot}, {s.duration:g} s each "
          f"(metrics after {s.settling:g} s), error against the {runs[0].ground_truth} motion")
    print(comparison_table(docs, predictors, scenarios))
    if args.paper:
        from rhmpc.studies.paper import paper_table

        print()
        print(paper_table(docs, predictors, scenarios))
    failed = [d for d in docs if "error" in d]
    for d in failed:
        print(f"failed: {d['predictor']} on {d['scenario']} seed {d['seed']}: {d['error']}")
    return 1 if failed else 0
