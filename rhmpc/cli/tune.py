"""`rhmpc tune`: parameter sweeps over run settings, parallel and resumable; and their report.

::

    rhmpc tune SPEC.toml [--jobs N | --scheduler ADDRESS] [--results FILE.jsonl] ...
    rhmpc tune report RESULTS.jsonl [--spec SPEC.toml] [--best-toml FILE] [--plot FILE.png]

The first word ``report`` selects the report; anything else is a sweep specification (see
:mod:`rhmpc.tuning.spec` for its format).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from rhmpc.cli import COMMANDS
from rhmpc.errors import UsageError, one_line

USAGE = ("rhmpc tune SPEC.toml [--jobs N | --scheduler ADDRESS] [--results FILE.jsonl] "
         "[--retry-failed] [--dry-run] [report options]\n"
         "       rhmpc tune report RESULTS.jsonl [--spec SPEC.toml] [report options]")

#: Options of one mode only (their argparse dest), to reject them in the other.
RUN_ONLY = ("jobs", "scheduler", "results", "retry_failed", "dry_run", "seed", "preset",
            "quiet")
REPORT_ONLY = ("spec",)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "tune", usage=USAGE,
        help=COMMANDS["tune"],
        description="Run a sweep specification (base settings, parameters as grid lists or "
        "sampled ranges, scenarios and seeds, objective) through a local process pool or a "
        "Dask cluster. Every finished evaluation is appended to a JSON-lines results file; "
        "re-running the same command skips what is done. Then print the ranked table and the "
        "best settings. 'rhmpc tune report RESULTS.jsonl' prints the table of a results file.",
        epilog="Spec format: the TOML files in examples/tune/ and the user guide (Tuning).")
    p.add_argument("target", nargs="+", metavar="SPEC.toml | report RESULTS.jsonl",
                   help="a sweep specification, or 'report' and a results file")
    run = p.add_argument_group("sweep options")
    run.add_argument("--jobs", type=int, default=None,
                     help="evaluations in parallel (default: the number of cores; with "
                     "--scheduler: the cluster's threads)")
    run.add_argument("--scheduler", metavar="ADDRESS",
                     help="run on a dask.distributed cluster (e.g. tcp://host:8786) instead of "
                     "local processes; needs the 'dask' extra on this machine and the workers")
    run.add_argument("--results", metavar="FILE.jsonl",
                     help="results file (default: SPEC's stem + .results.jsonl in the current "
                     "directory)")
    run.add_argument("--retry-failed", action="store_true", default=None,
                     help="run again the evaluations recorded as failed")
    run.add_argument("--seed", type=int, default=None,
                     help="seed of the random/lhs sampler (overrides sampler.seed; the run "
                     "seeds are evaluate.seeds)")
    run.add_argument("--preset", default=None, metavar="NAME",
                     help="apply a named operating point to the spec's base settings "
                     "(tuna2013: Tuna et al. 2013 Tables I-III)")
    run.add_argument("--dry-run", action="store_true", default=None,
                     help="list the points and what is left to run, run nothing")
    run.add_argument("--quiet", action="store_true", default=None,
                     help="no progress on stderr (warnings and errors still show)")
    rep = p.add_argument_group("report options")
    rep.add_argument("--spec", metavar="SPEC.toml",
                     help="(report) rank by this spec's objective and only its points")
    rep.add_argument("--top", type=int, default=20, help="rows of the table (default 20; 0 = all)")
    rep.add_argument("--best-toml", metavar="FILE.toml",
                     help="write the best settings (a simulate --config file)")
    rep.add_argument("--plot", metavar="FILE.png", help="objective against each parameter")
    rep.add_argument("--json", action="store_true", help="print the ranked points as JSON")
    p.set_defaults(func=run_command)


def run_command(args: argparse.Namespace) -> int:
    words = args.target
    if words[0] == "report":
        if len(words) != 2:
            raise UsageError("usage: rhmpc tune report RESULTS.jsonl [options]")
        _reject(args, RUN_ONLY, "report")
        return report(args, Path(words[1]))
    if len(words) != 1:
        raise UsageError(f"expected one SPEC.toml, got {' '.join(words)!r} (or: rhmpc tune "
                         "report RESULTS.jsonl)")
    _reject(args, REPORT_ONLY, "a sweep")
    return sweep(args, Path(words[0]))


def _reject(args: argparse.Namespace, names: tuple[str, ...], mode: str) -> None:
    for name in names:
        if getattr(args, name, None) is not None:
            raise UsageError(f"--{name.replace('_', '-')} does not apply to {mode}")


def _check_outputs(args: argparse.Namespace, inputs: tuple = ()) -> None:
    """--plot and --best-toml must be writable, and none of ``inputs`` (the spec, the results
    file), before a sweep starts."""
    from rhmpc import io

    for option, path in (("--plot", args.plot), ("--best-toml", args.best_toml)):
        if path:
            io.check_output(path, option, inputs=inputs)


def sweep(args: argparse.Namespace, spec_path: Path) -> int:
    from rhmpc.tuning.progress import format_duration, note
    from rhmpc.tuning.runner import pending
    from rhmpc.tuning.spec import load_spec, with_sampler_seed
    from rhmpc.tuning.store import read_results
    from rhmpc.tuning.sweep import execute, log_keys, points_table, speed_words

    spec = load_spec(spec_path)
    if args.preset is not None:
        import dataclasses

        from rhmpc.experiment.presets import apply_preset

        spec = dataclasses.replace(spec, base=apply_preset(spec.base, args.preset))
    if args.seed is not None:
        spec = with_sampler_seed(spec, args.seed, where=str(spec_path))
    if args.jobs is not None and args.jobs < 1:
        raise UsageError("--jobs must be >= 1")
    results_path = Path(args.results or f"{spec_path.stem}.results.jsonl")
    _check_outputs(args, (spec_path, results_path))
    tasks = spec.tasks()
    points = list(dict.fromkeys(t.point for t in tasks))
    existing = read_results(results_path)
    todo, n_ok, n_failed = pending(tasks, existing, retry_failed=bool(args.retry_failed))
    quiet = bool(args.quiet)
    if skipped := existing.skipped(results_path):
        print(f"rhmpc tune: warning: {one_line(skipped)}", file=sys.stderr)
    note(f"rhmpc tune: sweep '{spec.name}': {len(points)} points × {len(spec.evaluations())} "
         f"evaluations = {len(tasks)}; done {n_ok}, failed {n_failed}, to run {len(todo)}; "
         f"results {results_path}", quiet)
    if args.dry_run:
        print("\n".join(points_table(spec, tasks, existing)))
        return 0
    outcome = None
    if todo:
        outcome = execute(spec, todo, results_path, args.jobs, args.scheduler, quiet)
        note(f"rhmpc tune: {outcome.written} evaluation(s) in "
             f"{format_duration(outcome.elapsed_s)} = {outcome.evaluations_per_minute:.1f} "
             f"evaluations per minute{speed_words(outcome.records)}", quiet)
    code = report_records(args, read_results(results_path).records, spec.objective, points,
                          str(results_path), title=f"sweep '{spec.name}'",
                          log_keys=log_keys(spec))
    if outcome is not None and outcome.interrupted:
        print(f"rhmpc tune: interrupted; {outcome.written} evaluation(s) written this time, "
              f"{len(todo) - outcome.written} left; run the same command again to resume",
              file=sys.stderr)
        return 130
    latest = read_results(results_path).latest()
    failed = sum(1 for t in tasks if latest.get(t.key, {}).get("status") == "failed")
    if failed:
        print(f"rhmpc tune: {failed} evaluation(s) failed (see the report; --retry-failed "
              "runs them again)", file=sys.stderr)
        return 1
    return code


def report(args: argparse.Namespace, results_path: Path) -> int:
    from rhmpc.tuning.report import objective_of
    from rhmpc.tuning.store import read_results

    if not os.path.lexists(results_path):
        raise UsageError(f"{results_path}: no such file")
    _check_outputs(args, (results_path, *([args.spec] if args.spec else [])))
    data = read_results(results_path)
    if not data.records:
        raise UsageError(f"{results_path}: no results yet"
                         + (f" ({data.skipped(results_path).split(': ', 1)[1]})"
                            if data.bad_lines else ""))
    if skipped := data.skipped(results_path):
        print(f"rhmpc tune: warning: {one_line(skipped)}", file=sys.stderr)
    points, log_keys = None, None
    if args.spec:
        from rhmpc.tuning.spec import load_spec
        from rhmpc.tuning.sweep import log_keys as sweep_log_keys

        spec = load_spec(args.spec)
        objective = spec.objective
        points = list(dict.fromkeys(t.point for t in spec.tasks()))
        title = f"sweep '{spec.name}'"
        log_keys = sweep_log_keys(spec)
    else:
        objective = objective_of(data.records)
        names = list(dict.fromkeys(r.get("sweep") for r in data.records if r.get("sweep")))
        title = f"sweep '{', '.join(names)}'" if names else str(results_path)
    return report_records(args, data.records, objective, points, str(results_path), title,
                          log_keys)


def report_records(args, records, objective, points, results: str, title: str,
                   log_keys=None) -> int:
    """Print the ranked table (or JSON), write --best-toml and --plot; the exit code."""
    from rhmpc.tuning.figure import plot_objective
    from rhmpc.tuning.objective import check_objective_metrics
    from rhmpc.tuning.report import best, best_toml, format_table, summarize
    from rhmpc.tuning.sweep import best_settings

    ok = [r for r in records if r.get("status") == "ok" and isinstance(r.get("metrics"), dict)]
    if ok:
        check_objective_metrics(objective, ok[-1]["metrics"])
    summaries = summarize(records, objective, points)
    if not summaries:
        print("rhmpc tune: no results for these points yet", file=sys.stderr)
        return 0
    top = best(summaries)
    if args.best_toml:
        if top is None:
            raise UsageError("--best-toml: no point has finished all its evaluations "
                             "successfully")
        from rhmpc import io

        io.write_text(args.best_toml, best_toml(top, objective, results))
    if args.plot:
        plot_objective(summaries, objective, args.plot, title=f"rhmpc tune: {title}",
                       log_keys=log_keys)
    if args.json:
        json.dump({"objective": objective.to_dict(), "results": results,
                   "points": [dict(rank=i, **s.to_dict()) for i, s in enumerate(summaries, 1)],
                   "best_settings": best_settings(top)}, sys.stdout, indent=2)
        print()
        return 0
    n_eval = sum(s.n_ok + s.n_failed for s in summaries)
    print(f"rhmpc tune: {title}: {len(summaries)} points, {n_eval} evaluations; objective "
          f"{objective.describe()} (lower is better; mean ± sd over scenarios × seeds)")
    print(format_table(summaries, objective, top=args.top or None))
    if top is None:
        print("\nno point has finished all its evaluations successfully yet")
        return 0
    print(f"\nbest settings (rhmpc simulate --config FILE.toml"
          f"{'; written to ' + args.best_toml if args.best_toml else '; --best-toml FILE'}):")
    print(best_toml(top, objective, results))
    if args.plot:
        print(f"figure: {args.plot}")
    return 0


