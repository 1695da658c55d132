"""Running a sweep's evaluations through any ``concurrent.futures.Executor``, resumably.

:func:`run_sweep` keeps at most ``window`` evaluations in flight, writes each finished one to the
results file as soon as it arrives (so an interruption loses no finished result), and survives
a dead worker: a broken process pool is rebuilt and the evaluations it was running are tried
again, up to ``max_attempts`` times each before being recorded as failed. A local
``ProcessPoolExecutor`` (:func:`process_pool`) and dask.distributed's ``Client.get_executor()``
go through the same code (:func:`executors` picks one from the command line's ``--jobs`` and
``--scheduler``); ``rhmpc tune`` and ``rhmpc compare`` both run through it.

The workers of :func:`~rhmpc.tuning.workers.process_pool` die with the process that started them,
so that a sweep killed with SIGKILL leaves no worker behind; the results file is intact and the
same command resumes it.
"""

from __future__ import annotations

import os
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

from rhmpc.errors import UsageError
from rhmpc.tuning.evaluate import Task, evaluate_task, record_for
from rhmpc.tuning.scheduler import connect
from rhmpc.tuning.store import ResultsFile, ResultsWriter
from rhmpc.tuning.workers import process_pool, stop_executor

__all__ = ["HEARTBEAT_S", "Executors", "SweepOutcome", "executors", "pending", "process_pool",
           "run_sweep"]


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
    by_key : dict[str, dict]
        The same records by their task's key.
    """

    submitted: int = 0
    ok: int = 0
    failed: int = 0
    interrupted: bool = False
    pool_restarts: int = 0
    elapsed_s: float = 0.0
    records: list[dict] = field(default_factory=list)
    by_key: dict[str, dict] = field(default_factory=dict)

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
    writer: ResultsWriter | None,
    executor_factory: Callable[[], Executor],
    window: int,
    *,
    evaluate: Callable[..., dict] = evaluate_task,
    extra: dict | None = None,
    on_result: Callable[[dict], None] | None = None,
    heartbeat: Callable[[], None] | None = None,
    max_attempts: int = 2,
    failed: Callable[[Task, str], dict] | None = None,
) -> SweepOutcome:
    """Run ``tasks`` through executors from ``executor_factory``, appending each result.

    Parameters
    ----------
    tasks : iterable of Task
        Evaluations to run (already filtered by :func:`pending`); any objects with a unique
        ``key`` that ``evaluate`` and ``failed`` take.
    writer : ResultsWriter or None
        Open results file; every finished record is appended before ``on_result`` sees it
        (None: the records are only kept in the outcome).
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
    failed : callable, optional
        ``failed(task, error) -> record`` of a task that the executor could not run (default:
        a results line with status ``"failed"``). A record with ``status`` other than
        ``"ok"``, or without ``status`` and with ``error``, counts as failed.

    Returns
    -------
    SweepOutcome
        Counts; ``interrupted`` is set instead of propagating ``KeyboardInterrupt``.
    """
    if failed is None:
        def failed(task: Task, error: str) -> dict:
            return record_for(task, "failed", **(extra or {}), error=error)
    sweep = _Sweep(deque(tasks), writer, executor_factory, max(1, int(window)), evaluate,
                   extra, on_result, max_attempts, failed)
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
                 on_result: Callable[[dict], None] | None, max_attempts: int,
                 failed: Callable[[Task, str], dict]) -> None:
        self.queue, self.writer, self.executor_factory = queue, writer, executor_factory
        self.window, self.evaluate, self.extra = window, evaluate, extra
        self.on_result, self.max_attempts, self.failed = on_result, max_attempts, failed
        self.outcome = SweepOutcome(submitted=len(queue))
        self.inflight: dict[Future, Task] = {}
        self.attempts: dict[str, int] = {}

    def record(self, record: dict, task: Task) -> None:
        """Append a finished record to the file and the outcome's counts."""
        if self.writer is not None:
            self.writer.append(record)
        self.outcome.records.append(record)
        self.outcome.by_key[task.key] = record
        if record.get("status", "failed" if "error" in record else "ok") == "ok":
            self.outcome.ok += 1
        else:
            self.outcome.failed += 1

    def finish(self, record: dict, task: Task) -> None:
        self.record(record, task)
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
                self.finish(self.failed(task, f"worker died {n} times while running this "
                                        f"evaluation ({type(exc).__name__}: {exc})"), task)
            return True
        except Exception as exc:  # the executor could not run it (e.g. dask KilledWorker)
            self.finish(self.failed(task, f"{type(exc).__name__}: {exc}"), task)
            return False
        self.finish(record, task)
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
            task = self.inflight.pop(fut)
            try:
                record = fut.result()
            except BaseException:  # unfinished or broken: left for the resume
                continue
            self.record(record, task)
        stop_executor(executor, self.inflight)


@dataclass
class Executors:
    """Where the evaluations run: a factory of executors, how many run at once, and in words.

    Attributes
    ----------
    factory : callable
        Returns a fresh executor (:func:`run_sweep`'s ``executor_factory``).
    window : int
        Evaluations in flight at once.
    where : str
        ``"2 local process(es)"`` or ``"Dask cluster ADDRESS (8 in flight)"``.
    client : object or None
        The ``distributed.Client``, closed by :meth:`close`.
    """

    factory: Callable[[], Executor]
    window: int
    where: str
    client: object | None = None

    def close(self) -> None:
        if self.client is not None:
            self.client.close()


def executors(jobs: int | None, scheduler: str | None, tasks: int,
              start_method: str = "spawn") -> Executors:
    """Local worker processes (``jobs``, default the cores, at most ``tasks``) or, with
    ``scheduler``, a dask.distributed cluster (``jobs`` in flight, default its threads).

    Raises
    ------
    UsageError
        ``jobs`` below 1, dask.distributed missing, or the scheduler unreachable, not Dask's,
        or silent (:func:`rhmpc.tuning.scheduler.connect`).
    """
    if jobs is not None and jobs < 1:
        raise UsageError("--jobs must be >= 1")
    if not scheduler:
        window = max(1, min(jobs or os.cpu_count() or 1, tasks))
        return Executors(lambda: process_pool(window, start_method=start_method), window,
                         f"{window} local process(es)")
    client, threads = connect(scheduler)
    window = jobs or max(1, threads)
    return Executors(lambda: client.get_executor(pure=False), window,
                     f"Dask cluster {scheduler} ({window} in flight)", client)
