"""A sweep as ``rhmpc tune`` runs and reports it: its pending evaluations run with a bar on
stderr, the table of its points, its speed in words, the best point's settings."""

from __future__ import annotations

import sys
from pathlib import Path

from rhmpc.errors import UsageError, one_line
from rhmpc.tuning.progress import speed_phrase
from rhmpc.tuning.report import align, best_config, format_value

__all__ = ["best_settings", "execute", "log_keys", "points_table", "speed_words"]


def execute(spec, todo: list, results_path: Path, jobs: int | None, scheduler: str | None,
            quiet: bool = False):
    """Run the pending evaluations ``todo`` of ``spec`` on local processes (``jobs``) or a Dask
    cluster (``scheduler``), each appended to ``results_path`` as it finishes, with a bar on
    stderr; the first successful one's metrics are checked against the objective (a warning:
    the runs are still worth keeping). Returns the :class:`~rhmpc.tuning.runner.SweepOutcome`."""
    from rhmpc.tuning.objective import check_objective_metrics
    from rhmpc.tuning.progress import Heartbeat, note, progress_bar
    from rhmpc.tuning.runner import executors, run_sweep
    from rhmpc.tuning.store import ResultsWriter

    backend = executors(jobs, scheduler, len(todo))
    window, where = backend.window, backend.where
    note(f"rhmpc tune: running {len(todo)} evaluation(s) on {where}", quiet)
    bar = progress_bar(len(todo), "eval", f"tune {spec.name}", quiet)
    failures = 0
    checked = False

    def on_result(record: dict) -> None:
        nonlocal failures, checked
        failures += record.get("status") != "ok"
        if not checked and record.get("status") == "ok":
            checked = True
            try:
                check_objective_metrics(spec.objective, record["metrics"])
            except UsageError as exc:  # the runs are still worth keeping: warn, go on
                bar.write(f"rhmpc tune: warning: {one_line(exc)}", file=sys.stderr)
        bar.update(1)
        if failures:
            bar.set_postfix(failed=failures)

    try:
        with ResultsWriter(results_path) as writer:
            outcome = run_sweep(todo, writer, backend.factory, window, extra=_extra(spec),
                                on_result=on_result, heartbeat=Heartbeat(bar))
    finally:
        bar.close()
        backend.close()
    return outcome


def _extra(spec) -> dict:
    """What every results line of the sweep carries: its name, objective and evaluations."""
    return {"sweep": spec.name, "objective": spec.objective.to_dict(),
            "evaluations_per_point": len(spec.evaluations())}


def speed_words(records: list[dict]) -> str:
    """``; each ran 4.1× faster than real time`` from the successful records' timings."""
    ok = [r for r in records if r.get("status") == "ok"]
    simulated = sum(float(r.get("settings", {}).get("loop", {}).get("duration", 0.0))
                    for r in ok)
    wall = sum(float(r.get("timing", {}).get("wall_s", 0.0)) for r in ok)
    if not (simulated > 0 and wall > 0):
        return ""
    return f"; each ran {speed_phrase(simulated, wall)}"


def points_table(spec, tasks: list, existing) -> list[str]:
    """The lines of ``--dry-run``: each point, its evaluations done (in the results
    ``existing``) and its parameters."""
    latest = existing.latest()
    seen: dict[str, list] = {}
    for t in tasks:
        seen.setdefault(t.point, []).append(t)
    keys = [p.key for p in spec.parameters]
    rows = [["point", "done", *keys, "note"]]
    for i, ts in enumerate(seen.values(), 1):
        done = sum(1 for t in ts if latest.get(t.key, {}).get("status") == "ok")
        rows.append([str(i), f"{done}/{len(ts)}",
                     *(format_value(ts[0].parameters.get(k)) for k in keys),
                     "base" if ts[0].base else ""])
    return align(rows, [True, True, *([False] * (len(keys) + 1))])


def log_keys(spec) -> list[str]:
    """The spec's parameters sampled on a log scale (plotted on log axes)."""
    return [p.key for p in spec.parameters if p.is_range and p.scale == "log"]


def best_settings(summary) -> dict | None:
    """The settings of the best point (``summary``) as a run's TOML tables, or None."""
    if summary is None:
        return None
    return best_config(summary).to_dict()
