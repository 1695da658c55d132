"""Local worker processes that die with their parent, and stopping them at once.

A sweep or a comparison killed with SIGKILL cannot clean up after itself: its workers (each a
full interpreter with the run stack loaded) would go on running, and the multiprocessing
resource tracker with them. :func:`process_pool`'s workers end with the process that started
them, however it ends (:func:`die_with_parent`); :func:`stop_executor` ends them on Ctrl-C
without waiting for the runs in flight.

Only the standard library is imported here, so that a worker starts quickly.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import signal
import sys
import threading
import time
from collections.abc import Iterable
from concurrent.futures import Executor, Future, ProcessPoolExecutor

__all__ = ["TERMINATE_GRACE_S", "WATCHDOG_PERIOD_S", "die_with_parent", "process_pool",
           "program_dies_with_parent", "stop_executor", "worker_init"]

#: Linux ``prctl`` option: the signal a process receives when its parent dies.
_PR_SET_PDEATHSIG = 1
#: Seconds between two looks at the parent where ``prctl`` is not available.
WATCHDOG_PERIOD_S = 0.5


def _parent_death_signal(sig: int) -> bool:
    """Ask Linux to send ``sig`` to this process when its parent dies; False if not Linux."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)  # the process's own symbols: libc's prctl
        return libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch_parent(parent: int) -> None:
    """Exit as soon as the parent is gone (this process is re-parented)."""
    while os.getppid() == parent:
        time.sleep(WATCHDOG_PERIOD_S)
    os._exit(1)


def die_with_parent(parent: int) -> None:
    """Make the calling process end when process ``parent`` ends, however it ends.

    On Linux the kernel kills it (``PR_SET_PDEATHSIG`` with SIGKILL); elsewhere a daemon thread
    polls the parent's pid every :data:`WATCHDOG_PERIOD_S` seconds. If the parent is already
    gone, the process exits at once.

    Parameters
    ----------
    parent : int
        The pid of the process that started this one.
    """
    if not _parent_death_signal(signal.SIGKILL):
        threading.Thread(target=_watch_parent, args=(parent,), daemon=True,
                         name="die-with-parent").start()
    if os.getppid() != parent:  # died before the signal was armed
        os._exit(1)


def program_dies_with_parent() -> None:
    """``preexec_fn`` of a program started with :mod:`subprocess`: it gets SIGKILL when the
    process that started it ends (Linux; elsewhere nothing)."""
    _parent_death_signal(signal.SIGKILL)


def worker_init(parent: int) -> None:
    """Worker initializer: Ctrl-C is the parent's to handle (it stops the workers itself), and
    the worker dies with the parent (:func:`die_with_parent`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(parent)


def process_pool(jobs: int, start_method: str = "spawn") -> ProcessPoolExecutor:
    """A local pool of ``jobs`` processes that ignore Ctrl-C and die with this process.

    Parameters
    ----------
    jobs : int
        Worker processes.
    start_method : str
        ``"spawn"`` (fresh interpreters, the default) or ``"fork"`` (copies of this process:
        no start-up imports, for runs of a parent that has loaded the run stack already).
    """
    return ProcessPoolExecutor(max_workers=jobs,
                               mp_context=multiprocessing.get_context(start_method),
                               initializer=worker_init, initargs=(os.getpid(),))


#: Seconds a terminated worker has to end before it is killed.
TERMINATE_GRACE_S = 1.0


def stop_executor(executor: Executor, futures: Iterable[Future]) -> None:
    """Cancel what is queued and stop the workers without waiting for running evaluations.

    Each worker gets SIGTERM, then SIGKILL if it has not ended within
    :data:`TERMINATE_GRACE_S`, and is reaped: no worker outlives this call, so that the
    executor's own clean-up at exit has no process to wait for.
    """
    for fut in futures:
        fut.cancel()
    if isinstance(executor, ProcessPoolExecutor):
        processes = list((getattr(executor, "_processes", None) or {}).values())
        for process in processes:
            if process.is_alive():
                process.terminate()
        deadline = time.monotonic() + TERMINATE_GRACE_S
        for process in processes:
            process.join(max(0.0, deadline - time.monotonic()))
            if process.is_alive():
                process.kill()
                process.join()
    executor.shutdown(wait=False, cancel_futures=True)
