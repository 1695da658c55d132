"""Running a comparison's jobs: in parallel through the sweep runner of ``rhmpc tune``
(:func:`rhmpc.tuning.runner.run_sweep`), local worker processes or a dask.distributed
cluster, with a progress bar on stderr; with the literature's split, each recording's open
loop first (:mod:`rhmpc.compare.loop_gap`), whose fitted models the closed loops load. The
whole is estimated before any of it, and the bar's time left follows the runs as they finish
(:mod:`rhmpc.compare.estimate`).
"""

from __future__ import annotations

import sys
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from rhmpc.compare.estimate import PROBE_S
from rhmpc.compare.jobs import Job, evaluate_job, failed_doc, labelled, setting_of
from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig
from rhmpc.experiment.fitting import with_models
from rhmpc.tuning.progress import format_duration, note, speed_phrase

__all__ = ["SCHEMA", "Comparison", "Execution", "document", "footer", "header", "run_comparison"]


#: The version of the comparison's document (docs/guide/json.md); a change to its keys bumps it.
#: 2: the runs under ``runs`` (``results`` before).
SCHEMA = "rhmpc.compare/2"


@dataclass(frozen=True)
class Execution:
    """How a comparison's runs are run.

    Attributes
    ----------
    workers : int or None
        Local processes (default: the cores), or with ``scheduler`` the runs in flight
        (default: the cluster's threads).
    scheduler : str or None
        A dask.distributed scheduler's address; None: local processes.
    split : (int, int) or None
        The literature's split of the recordings (TRAIN, END): the open loop runs first.
    models : tuple of str
        Saved models the runs load (``--model``): the open loop's are then not shared.
    quiet : bool
        No progress on stderr.
    """

    workers: int | None = None
    scheduler: str | None = None
    split: tuple[int, int] | None = None
    models: tuple[str, ...] = ()
    quiet: bool = False


@dataclass
class Comparison:
    """What a comparison ran: the jobs, their documents (in the jobs' order, those that
    finished), where they ran, and, with a split, each column's open loop."""

    jobs: list[Job]
    docs: list[dict]
    done: list[Job]
    interrupted: bool
    elapsed_s: float
    where: str
    open_loops: dict[str, dict] = field(default_factory=dict)

    def axes(self, done: bool = False) -> tuple[list[str], list[str]]:
        """The table's predictors and columns, in the jobs' order (of the runs done)."""
        jobs = self.done if done else self.jobs
        return (list(dict.fromkeys(job.config.predictor for job in jobs)),
                list(dict.fromkeys(job.column for job in jobs)))

    def setting(self, done: bool = False) -> str:
        """Tuna's setting of the runs (:func:`rhmpc.compare.jobs.setting_of`)."""
        return setting_of([job.config for job in (self.done if done else self.jobs)])


def run_comparison(todo: list[Job], how: Execution) -> Comparison:
    """Run every job (with a split, each column's open loop first, whose models the runs load
    instead of fitting again), the whole estimated before any of it and the time left kept on
    the bar (:mod:`rhmpc.compare.estimate`)."""
    from rhmpc.tuning.runner import executors

    plans = open_plans(todo, how) if how.split else {}
    fitted_here = how.split and "torch" in sys.modules  # the plans timed PyTorch networks
    backend = executors(how.workers, how.scheduler, len(todo),
                        start_method="spawn" if fitted_here else "fork")
    try:
        estimates = _estimate(todo, plans, backend, how)
        with tempfile.TemporaryDirectory(prefix="rhmpc-models-") as folder:
            beside, todo = open_loops(todo, plans, how, Path(folder)) if plans else ({}, todo)
            outcome = execute(todo, backend, estimates, how)
    finally:
        backend.close()
    done = [job for job in todo if job.key in outcome.by_key]
    return Comparison(todo, [outcome.by_key[job.key] for job in done], done,
                      outcome.interrupted, outcome.elapsed_s, backend.where, beside)


def _estimate(todo: list[Job], plans: dict, backend, how: Execution) -> dict[str, float]:
    """Each job's estimate (key → seconds), after the whole is said; none with ``quiet``,
    where no one reads it."""
    from rhmpc.compare.estimate import job_estimates, makespan, probe
    from rhmpc.experiment.fit_plan import duration

    if how.quiet:
        return {}
    note(f"rhmpc compare: timing a {PROBE_S:g}-s run of hold on {todo[0].column}, and each "
         "predictor on a few samples, for the estimate", how.quiet)
    measured = probe(todo[0])
    if measured is None:
        return {}
    steps = {column: plan.steps for column, plan in plans.items()}
    estimates = job_estimates(todo, measured, steps)
    runs = makespan(estimates, min(backend.window, len(todo)))
    opened = sum(p.fitting_s + p.scoring_s() for p in plans.values())
    fits = sum(p.fitting_s for p in plans.values())
    note(f"rhmpc compare: about {duration(opened + runs)} in all: "
         + (f"the open loops {duration(opened)} ({duration(fits)} of fitting), then "
            if plans else "")
         + f"{len(todo)} run(s) on {backend.where} {duration(runs)} (each "
         + (f"{lo}–{hi})" if (lo := duration(min(estimates))) != (hi := duration(max(estimates)))
            else f"about {lo})"), how.quiet)
    return {job.key: t for job, t in zip(todo, estimates, strict=True)}


def open_plans(todo: list[Job], how: Execution) -> dict:
    """Per recording column of a split: the plan of its open loop
    (:func:`rhmpc.compare.loop_gap.beside_plan`)."""
    from rhmpc.compare.loop_gap import beside_plan

    out = {}
    for column in dict.fromkeys(job.column for job in todo):
        config = next(job.config for job in todo if job.column == column)
        names = list(dict.fromkeys(job.config.predictor for job in todo if job.column == column))
        try:
            out[column] = beside_plan(config.data, config.data_read, how.split, names,
                                      config.reference.prediction_points, config.seed)
        except ValueError as exc:
            raise UsageError(f"{column}: {exc}") from None
    return out


def open_loops(todo: list[Job], plans: dict, how: Execution,
               folder: Path) -> tuple[dict[str, dict], list[Job]]:
    """Per recording column of a split: every predictor's open-loop forecast of the scored
    samples one sample ahead (:func:`rhmpc.compare.loop_gap.open_loop_beside`), made here
    before the closed loops run; and the jobs, whose predictors fitted before the run load
    the models fitted there (saved in ``folder``) instead of fitting again (fit once, run
    many), unless ``models`` names others or the runs go to a cluster."""
    from rhmpc.compare.loop_gap import open_loop_beside

    out, share, split = {}, not (how.models or how.scheduler), how.split
    for i, (column, plan) in enumerate(plans.items()):
        note(f"rhmpc compare: the open loop on {column}, split {split[0]}:{split[1]}",
             how.quiet)
        save = folder / str(i) if share else None
        if save is not None:
            save.mkdir()
        try:
            out[column] = open_loop_beside(
                plan, None if how.quiet else (lambda text: note(f"  {text}", False)), save)
        except ValueError as exc:
            raise UsageError(f"{column}: {exc}") from None
        if save is not None:
            files = sorted(save.iterdir())
            todo = [Job(j.key, j.column, with_models(j.config, files, strict=False))
                    if j.column == column else j for j in todo]
    return out, todo


def execute(todo: list[Job], backend, estimates: dict[str, float], how: Execution):
    """Run the jobs through the sweep runner on ``backend``, with a bar on stderr whose time
    left follows the runs' estimates (:class:`rhmpc.compare.estimate.Remaining`).

    Local worker processes are forked (the parent has the run stack loaded), or started afresh
    where the open loops of a split may have run PyTorch here (a fork does not carry its
    threads: the workers hung), and die with this process; a scheduler sends the jobs to a
    Dask cluster. Ctrl-C stops the workers at once and keeps the runs that finished.

    Returns
    -------
    SweepOutcome
        Documents by job key (a run that failed or whose worker died twice has ``error``),
        ``interrupted``.
    """
    from rhmpc.compare.estimate import Remaining
    from rhmpc.tuning.progress import Heartbeat, progress_bar
    from rhmpc.tuning.runner import run_sweep

    note(f"rhmpc compare: running {len(todo)} run(s) on {backend.where}", how.quiet)
    bar = progress_bar(len(todo), "run", "compare", how.quiet,
                       bar_format="{desc}: {n_fmt}/{total_fmt} runs |{bar}| {elapsed}{postfix}")
    left = Remaining(estimates, backend.window)
    keys = {(j.column, j.config.predictor, j.config.seed): j.key for j in todo}
    failed = 0

    def show() -> None:
        words = [w for w in (left.text(), f"{failed} failed" if failed else "") if w]
        bar.set_postfix_str(", ".join(words), refresh=False)

    def on_result(doc: dict) -> None:
        nonlocal failed
        failed += "error" in doc
        took = doc.get("build_s", 0.0) + doc["wall_s"] if "wall_s" in doc else None
        left.finished(keys.get((doc.get("scenario"), doc.get("predictor"), doc.get("seed")),
                               ""), took)
        show()
        bar.update(1)

    def failed_run(job: Job, error: str) -> dict:
        return labelled(failed_doc(job, error), job)

    beat = Heartbeat(bar)

    def heartbeat() -> None:
        show()
        beat()

    show()
    try:
        return run_sweep(todo, None, backend.factory, backend.window, evaluate=evaluate_job,
                         on_result=on_result, heartbeat=heartbeat, failed=failed_run)
    finally:
        bar.close()


def document(comparison: Comparison, seeds: Sequence[int]) -> dict:
    """What ``--json`` prints: the runs, the seeds, whether it was interrupted, the cells
    (:func:`rhmpc.compare.table.cells_document`) and, with a split, the loop gap."""
    from rhmpc.compare.table import cells_document

    docs = comparison.docs
    predictors, columns = comparison.axes(done=True)
    out = {"schema": SCHEMA, "runs": docs, "seeds": list(seeds),
           "interrupted": comparison.interrupted,
           "cells": cells_document(docs, predictors, columns)}
    if comparison.open_loops:
        from rhmpc.compare.loop_gap import gap_rows

        out["loop_gap"] = gap_rows(docs, comparison.open_loops)
    return out


def header(todo: Sequence[Job], recordings: bool, seeds: int) -> str:
    """What runs: how many, of what, on which robot, how long, scored against what."""
    runs = [job.config for job in todo]
    n_pred = len({c.predictor for c in runs})
    n_col = len({job.column for job in todo})
    what = "recording" if recordings else "scenario"
    return (f"rhmpc compare: {len(runs)} runs ({n_pred} predictor{'s' * (n_pred != 1)} × "
            f"{n_col} {what}{'s' * (n_col != 1)} × {seeds} seed{'s' * (seeds != 1)}) "
            f"on robot {runs[0].robot}\n  {_lengths(runs)}, error against the "
            f"{runs[0].ground_truth} motion")


def footer(comparison: Comparison) -> str:
    """``4 runs in 12 s on 2 local process(es); each run 3.4× faster than real time``."""
    runs = [job.config for job in comparison.done]
    ok = [(d, c) for d, c in zip(comparison.docs, runs, strict=True) if "error" not in d]
    simulated = sum(c.loop.duration for _, c in ok)
    run_wall = sum(float(d.get("wall_s", 0.0)) for d, _ in ok)
    line = (f"rhmpc compare: {len(runs)} runs in {format_duration(comparison.elapsed_s)} on "
            f"{comparison.where}")
    if simulated > 0 and run_wall > 0:
        line += f"; each run {speed_phrase(simulated, run_wall)}"
    return line


def _lengths(runs: Sequence[RunConfig]) -> str:
    """``60 s each (metrics after 20 s)``, or each run's length where they differ."""
    spans = list(dict.fromkeys((c.loop.duration, c.loop.settling_s) for c in runs))
    if len(spans) == 1:
        return (f"{format_duration(spans[0][0])} each (metrics after "
                f"{format_duration(spans[0][1])})")
    return "; ".join(f"{format_duration(d)} (metrics after {format_duration(s)})"
                     for d, s in spans)
