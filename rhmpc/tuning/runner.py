"""Running a sweep's evaluations through any ``concurrent.futures.Executor``, resumably.

:func:`run_sweep` keeps at most ``window`` evaluations in flight, writes each finished one to the
results file as soon as it arrives (so an interruption loses no finished result), and survives
a dead worker: a broken process pool is rebuilt and the evaluations it was running are tried
again, up to ``max_attempts`` times each before being recorded as failed. A local
``ProcessPoolExecutor`` (:func:`process_pool`) and dask.distributed's ``Client.get_executor()``
go through the same code.

The workers of :func:`~rhmpc.tuning.workers.process_pool` die with the process that started them,
so that a sweep killed with SIGKILL leaves no worker behind; the results file is intact and the
same command resumes it.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Iterable
from concurrent.futures import (
    FIRST_COMPLETED,
    BrokenExecutor,
    CancelledError,
    Executor,
    Future,
    wait,
)
from dataclasses import dataclass, field

from rhmpc.tuning.evaluate import Task, evaluate_task, record_for
from rhmpc.tuning.store import ResultsFile, ResultsWriter
from rhmpc.tuning.workers import process_pool, stop_executor

__all__ = ["HEARTBEAT_S", "SweepOutcome", "pending", "process_pool", "run_sweep"]


@dataclass
class SweepOutcome:
    """What :func:`run_sweep` did.

    Attributes
    ----------
    submitted : int
        Evaluations it was asked to run.
    ok, failed : int
        Evaluations finished and written, by status.
    interrupted : bool
        Stopped by ``KeyboardInterrupt`` (the unfinished ones are left for a resume).
    pool_restarts : int
        Times a broken executor was replaced.
    elapsed_s : float
        Wall time of the sweep, from the first submission to the last result [s].
    records : list[dict]
        The records written, in completion order.
    """

    submitted: int = 0
    ok: int = 0
    failed: int = 0
    interrupted: bool = False
    pool_restarts: int = 0
    elapsed_s: float = 0.0
    records: list[dict] = field(default_factory=list)

    @property
    def written(self) -> int:
        return self.ok + self.failed

    @property
    def evaluations_per_minute(self) -> float:
        """Throughput ``60 · written / elapsed_s`` [1/min] (0 before anything was written)."""
        return 60.0 * self.written / self.elapsed_s if self.elapsed_s > 0 else 0.0


def pending(tasks: Iterable[Task], results: ResultsFile, retry_failed: bool = False
            ) -> tuple[list[Task], int, int]:
    """The tasks still to run, and how many are done (ok) and failed already.

    A key with an ``ok`` record is done; one whose latest record failed is skipped too unless
    ``retry_failed``.
    """
    latest = results.latest()
    todo, ok, failed = [], 0, 0
    for task in tasks:
        record = latest.get(task.key)
        if record is None:
            todo.append(task)
        elif record.get("status") == "ok":
            ok += 1
        elif retry_failed:
            todo.append(task)
        else:
            failed += 1
    return todo, ok, failed


#: Longest wait between two calls of :func:`run_sweep`'s ``heartbeat`` [s].
HEARTBEAT_S = 0.5


def run_sweep(
    tasks: Iterable[Task],
    writer: ResultsWriter,
    executor_factory: Callable[[], Executor],
    window: int,
    *,
    evaluate: Callable[..., dict] = evaluate_task,
    extra: dict | None = None,
    on_result: Callable[[dict], None] | None = None,
    heartbeat: Callable[[], None] | None = None,
    max_attempts: int = 2,
) -> SweepOutcome:
    """Run ``tasks`` through executors from ``executor_factory``, appending each result.

    Parameters
    ----------
    tasks : iterable of Task
        Evaluations to run (already filtered by :func:`pending`).
    writer : ResultsWriter
        Open results file; every finished record is appended before ``on_result`` sees it.
    executor_factory : callable
        Returns a fresh ``Executor``; called again when one breaks (a worker process died).
    window : int
        Evaluations in flight at once (the executor's parallelism).
    evaluate : callable
        ``evaluate(task, extra) -> record``, run in the workers; must be picklable for a
        process pool or a cluster.
    extra : dict, optional
        Passed to ``evaluate`` (added to every record).
    on_result : callable, optional
        Called with each written record (progress). Raising ``KeyboardInterrupt`` from it stops
        the sweep like Ctrl-C does.
    heartbeat : callable, optional
        Called at least every :data:`HEARTBEAT_S` seconds while evaluations are in flight
        (e.g. to redraw a progress bar).
    max_attempts : int
        A task whose worker died this many times is recorded as failed.

    Returns
    -------
    SweepOutcome
        Counts; ``interrupted`` is set instead of propagating ``KeyboardInterrupt``.
    """
    sweep = _Sweep(deque(tasks), writer, executor_factory, max(1, int(window)), evaluate,
                   extra, on_result, max_attempts)
    start = time.perf_counter()
    executor = executor_factory()
    try:
        while sweep.queue or sweep.inflight:
            broken = sweep.submit(executor)
            if not broken:
                done, _ = wait(list(sweep.inflight), return_when=FIRST_COMPLETED,
                               timeout=None if heartbeat is None else HEARTBEAT_S)
                if heartbeat is not None:
                    heartbeat()
                for fut in done:
                    broken |= sweep.settle(fut, sweep.inflight.pop(fut))
            if broken:
                executor = sweep.restart(executor)
    except KeyboardInterrupt:
        sweep.interrupt(executor)
    else:
        executor.shutdown(wait=True)
    sweep.outcome.elapsed_s = time.perf_counter() - start
    return sweep.outcome


class _Sweep:
    """The state of :func:`run_sweep`: the queue, what is in flight, attempts, the outcome."""

    def __init__(self, queue: deque, writer: ResultsWriter,
                 executor_factory: Callable[[], Executor], window: int,
                 evaluate: Callable[..., dict], extra: dict | None,
                 on_result: Callable[[dict], None] | None, max_attempts: int) -> None:
        self.queue, self.writer, self.executor_factory = queue, writer, executor_factory
        self.window, self.evaluate, self.extra = window, evaluate, extra
        self.on_result, self.max_attempts = on_result, max_attempts
        self.outcome = SweepOutcome(submitted=len(queue))
        self.inflight: dict[Future, Task] = {}
        self.attempts: dict[str, int] = {}

    def record(self, record: dict) -> None:
        """Append a finished record to the file and the outcome's counts."""
        self.writer.append(record)
        self.outcome.records.append(record)
        if record.get("status") == "ok":
            self.outcome.ok += 1
        else:
            self.outcome.failed += 1

    def finish(self, record: dict) -> None:
        self.record(record)
        if self.on_result is not None:
            self.on_result(record)

    def submit(self, executor: Executor) -> bool:
        """Fill the window; True if the executor turned out to be broken."""
        while self.queue and len(self.inflight) < self.window:
            task = self.queue.popleft()
            try:
                self.inflight[executor.submit(self.evaluate, task, self.extra)] = task
            except BrokenExecutor:
                self.queue.appendleft(task)
                return True
        return False

    def settle(self, fut: Future, task: Task) -> bool:
        """Handle one completed future; True if it showed the executor is broken."""
        try:
            record = fut.result()
        except CancelledError:
            self.queue.appendleft(task)
            return False
        except BrokenExecutor as exc:
            self.attempts[task.key] = n = self.attempts.get(task.key, 0) + 1
            if n < self.max_attempts:
                self.queue.appendleft(task)
            else:
                self.finish(record_for(task, "failed", **(self.extra or {}),
                                       error=f"worker died {n} times while running this "
                                       f"evaluation ({type(exc).__name__}: {exc})"))
            return True
        except Exception as exc:  # the executor could not run it (e.g. dask KilledWorker)
            self.finish(record_for(task, "failed", **(self.extra or {}),
                                   error=f"{type(exc).__name__}: {exc}"))
            return False
        self.finish(record)
        return False

    def restart(self, executor: Executor) -> Executor:
        """Every evaluation in flight is lost with a broken pool: collect them, start afresh."""
        done, _ = wait(list(self.inflight))
        for fut in done:
            self.settle(fut, self.inflight.pop(fut))
        executor.shutdown(wait=True)
        self.outcome.pool_restarts += 1
        return self.executor_factory()

    def interrupt(self, executor: Executor) -> None:
        """Ctrl-C: keep whatever finished meanwhile, then stop the rest."""
        self.outcome.interrupted = True
        for fut in [f for f in self.inflight if f.done() and not f.cancelled()]:
            self.inflight.pop(fut)
            try:
                record = fut.result()
            except BaseException:  # unfinished or broken: left for the resume
                continue
            self.record(record)
        stop_executor(executor, self.inflight)
