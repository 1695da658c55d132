"""Running a sweep's evaluations through any ``concurrent.futures.Executor``, resumably.

:func:`run_sweep` keeps at most ``window`` evaluations in flight, writes each finished one to the
results file as soon as it arrives (so an interruption loses no finished result), and survives
a dead worker: a broken process pool is rebuilt and the evaluations it was running are tried
again, up to ``max_attempts`` times each before being recorded as failed. A local
``ProcessPoolExecutor`` (:func:`process_pool`) and dask.distributed's ``Client.get_executor()``
go through the same code.
"""

from __future__ import annotations

import multiprocessing
import signal
import time
from collections import deque
from collections.abc import Callable, Iterable
from concurrent.futures import (
    FIRST_COMPLETED,
    BrokenExecutor,
    CancelledError,
    Executor,
    Future,
    ProcessPoolExecutor,
    wait,
)
from dataclasses import dataclass, field

from rhmpc.tuning.evaluate import Task, evaluate_task, record_for
from rhmpc.tuning.store import ResultsFile, ResultsWriter


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


def _ignore_sigint() -> None:
    """Worker initializer: Ctrl-C is handled by the parent, which stops the workers itself."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def process_pool(jobs: int) -> ProcessPoolExecutor:
    """A local pool of ``jobs`` fresh (spawned) processes that ignore Ctrl-C."""
    return ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                               initializer=_ignore_sigint)


def _stop(executor: Executor, futures: Iterable[Future]) -> None:
    """Cancel what is queued and stop the workers without waiting for running evaluations."""
    for fut in futures:
        fut.cancel()
    terminate = getattr(executor, "terminate_workers", None)  # Python >= 3.14
    if terminate is not None:
        terminate()
    elif isinstance(executor, ProcessPoolExecutor):
        for process in list((getattr(executor, "_processes", None) or {}).values()):
            if process.is_alive():
                process.terminate()
    executor.shutdown(wait=False)


def run_sweep(
    tasks: Iterable[Task],
    writer: ResultsWriter,
    executor_factory: Callable[[], Executor],
    window: int,
    *,
    evaluate: Callable[..., dict] = evaluate_task,
    extra: dict | None = None,
    on_result: Callable[[dict], None] | None = None,
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
    max_attempts : int
        A task whose worker died this many times is recorded as failed.

    Returns
    -------
    SweepOutcome
        Counts; ``interrupted`` is set instead of propagating ``KeyboardInterrupt``.
    """
    queue = deque(tasks)
    outcome = SweepOutcome(submitted=len(queue))
    inflight: dict[Future, Task] = {}
    attempts: dict[str, int] = {}
    window = max(1, int(window))
    start = time.perf_counter()

    def finish(record: dict) -> None:
        writer.append(record)
        outcome.records.append(record)
        if record.get("status") == "ok":
            outcome.ok += 1
        else:
            outcome.failed += 1
        if on_result is not None:
            on_result(record)

    def settle(fut: Future, task: Task) -> bool:
        """Handle one completed future; True if it showed the executor is broken."""
        try:
            record = fut.result()
        except CancelledError:
            queue.appendleft(task)
            return False
        except BrokenExecutor as exc:
            attempts[task.key] = attempts.get(task.key, 0) + 1
            if attempts[task.key] < max_attempts:
                queue.appendleft(task)
            else:
                finish(record_for(task, "failed", **(extra or {}),
                                  error=f"worker died {attempts[task.key]} times while running "
                                  f"this evaluation ({type(exc).__name__}: {exc})"))
            return True
        except Exception as exc:  # the executor could not run it (e.g. dask KilledWorker)
            finish(record_for(task, "failed", **(extra or {}),
                              error=f"{type(exc).__name__}: {exc}"))
            return False
        finish(record)
        return False

    executor = executor_factory()
    try:
        while queue or inflight:
            broken = False
            while queue and len(inflight) < window:
                task = queue.popleft()
                try:
                    inflight[executor.submit(evaluate, task, extra)] = task
                except BrokenExecutor:
                    queue.appendleft(task)
                    broken = True
                    break
            if not broken:
                done, _ = wait(list(inflight), return_when=FIRST_COMPLETED)
                for fut in done:
                    broken |= settle(fut, inflight.pop(fut))
            if broken:
                # every evaluation in flight is lost with the pool: collect them, start afresh
                done, _ = wait(list(inflight))
                for fut in done:
                    settle(fut, inflight.pop(fut))
                executor.shutdown(wait=True)
                executor = executor_factory()
                outcome.pool_restarts += 1
    except KeyboardInterrupt:
        outcome.interrupted = True
        # keep whatever finished meanwhile, then stop the rest
        for fut in [f for f in inflight if f.done() and not f.cancelled()]:
            task = inflight.pop(fut)
            try:
                record = fut.result()
            except BaseException:  # unfinished or broken: left for the resume
                continue
            writer.append(record)
            outcome.records.append(record)
            outcome.ok += record.get("status") == "ok"
            outcome.failed += record.get("status") != "ok"
        _stop(executor, inflight)
        outcome.elapsed_s = time.perf_counter() - start
        return outcome
    executor.shutdown(wait=True)
    outcome.elapsed_s = time.perf_counter() - start
    return outcome
