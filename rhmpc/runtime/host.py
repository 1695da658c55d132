"""The host's own wake-up latency, measured beside the controller in the same run.

The real-time Linux community measures what a host can do with ``cyclictest`` (Debian's
``rt-tests``): a thread that sleeps to an absolute time on ``CLOCK_MONOTONIC``
(``clock_nanosleep`` with ``TIMER_ABSTIME``), again and again, and records how late it wakes.
Where ``cyclictest`` is installed it runs, with the controller's interval (Ts), scheduling
policy, priority and processor; else the controller's own program runs as that probe
(``--probe``: the same loop, the same clock, no work). Either way the probe's wake-ups fall
half a period after the controller's, so that the two threads on one processor do not queue
behind each other.
"""

from __future__ import annotations

import os
import re
import resource
import shutil
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rhmpc import io

__all__ = ["HISTOGRAM_US", "Permits", "histogram_percentiles", "percentiles", "permits",
           "probe_command", "read_histogram", "read_int64", "read_probe"]

#: cyclictest's histogram: 1-µs bins up to this latency [µs] (beyond: its overflow count).
HISTOGRAM_US = 10_000


def probe_command(program: Path, *, epoch_ns: int, ticks: int, Ts: float, cpu: int,
                  priority: int, out: Path, phase_ns: int,
                  allowed: Permits | None = None) -> tuple[list[str], str]:
    """The probe's command and its name: cyclictest where installed, else ``program --probe``.

    cyclictest cannot start at the run's epoch: it runs for the run's length from when it
    starts (just before the epoch), its first thread's wake-ups at its own phase. It asks only
    for what the host permits (``allowed``); cyclictest cannot start without SCHED_FIFO
    ("Unable to change scheduling policy"), so there the controller's own loop is the probe,
    on the default scheduler as the controller then runs."""
    cyclictest = shutil.which("cyclictest")
    if cyclictest is not None and (allowed is None or allowed.fifo is None):
        seconds = max(1, round(ticks * Ts + 1))
        lock = allowed is None or allowed.mlock is None
        return [cyclictest, *(["--mlockall"] if lock else []), f"--priority={priority}",
                f"--affinity={cpu}",
                f"--interval={round(Ts * 1e6)}", f"--duration={seconds}", "--quiet",
                f"--histogram={HISTOGRAM_US}", f"--histfile={out}.hist"], "cyclictest"
    return [str(program), "--probe", "--epoch", str(epoch_ns), "--ticks", str(ticks),
            "--phase", str(phase_ns), "--cpu", str(cpu), "--priority", str(priority),
            "--out", str(out)], "rhmpc probe (the controller's loop without its work)"


def percentiles(values_us: np.ndarray) -> dict:
    """p50, p99 and max of latencies [µs] (None each without a value)."""
    values_us = np.asarray(values_us, dtype=float)
    if values_us.size == 0:
        return {"p50": None, "p99": None, "max": None}
    p50, p99 = np.percentile(values_us, [50, 99])
    return {"p50": round(float(p50), 1), "p99": round(float(p99), 1),
            "max": round(float(values_us.max()), 1)}


def read_histogram(text: str) -> tuple[np.ndarray, np.ndarray, float]:
    """(latencies [µs], counts, max [µs]) of a cyclictest histogram file (``--histfile``):
    lines ``µs count`` (one column per thread: summed), then ``# Max Latencies:`` and
    ``# Histogram Overflows:`` (the wake-ups beyond the last bin, counted at its edge)."""
    bins, counts = [], []
    for line in text.splitlines():
        if line.startswith("#") or not line.strip():
            continue
        fields = line.split()
        bins.append(int(fields[0]))
        counts.append(sum(int(f) for f in fields[1:]))
    overflow = re.search(r"# Histogram Overflows:\s*([\d\s]+)", text)
    biggest = re.search(r"# Max Latencies:\s*([\d\s]+)", text)
    over = sum(int(v) for v in overflow.group(1).split()) if overflow else 0
    values, weights = np.array([*bins, HISTOGRAM_US], float), np.array([*counts, over], float)
    top = max(int(v) for v in biggest.group(1).split()) if biggest else \
        (values[weights > 0][-1] if weights.any() else np.nan)
    return values, weights, float(top)


def histogram_percentiles(values: np.ndarray, weights: np.ndarray, top: float) -> dict:
    """p50, p99 and max [µs] of a histogram (bins ``values``, counts ``weights``)."""
    if weights.sum() == 0:
        return {"p50": None, "p99": None, "max": None}
    cumulative = np.cumsum(weights) / weights.sum()
    p50, p99 = (float(values[np.searchsorted(cumulative, q)]) for q in (0.5, 0.99))
    return {"p50": p50, "p99": p99, "max": top}


def read_int64(path: Path) -> np.ndarray:
    """A raw array of int64 the controller's program wrote (empty if it wrote none)."""
    if not path.is_file():
        return np.zeros(0, dtype=np.int64)
    return np.frombuffer(io.read_bytes(path, track=False), dtype=np.int64)


def read_probe(out: Path, tool: str, Ts: float) -> dict:
    """The probe's p50, p99 and max wake-up latency [µs], the fraction of its periods that
    began a period or more before it woke (``late_periods``: the deadline misses it would have
    had, a stall of L counting floor(L / Ts), as the controller's misses do) and its name."""
    if tool == "cyclictest":
        hist = Path(f"{out}.hist")
        text = io.read_bytes(hist, track=False).decode() if hist.is_file() else ""
        values, weights, top = read_histogram(text)
        found = histogram_percentiles(values, weights, top)
        # a wake-up L late finds floor(L / Ts) periods begun while it slept, which cyclictest
        # skips and a controller misses: the misses the host alone would cause
        skipped = weights * np.floor(values / (Ts * 1e6))
        late = skipped.sum() / max(weights.sum() + skipped.sum(), 1.0)
    else:
        us = read_int64(Path(f"{out}.wake")) * 1e-3
        found = percentiles(us)
        doc = Path(f"{out}.json")
        behind = io.read_json(doc, track=False)["ticks_behind"] if doc.is_file() else 0
        late = (np.sum(us >= Ts * 1e6) + behind) / max(us.size + behind, 1)
    return {**found, "late_periods": round(float(late), 6), "tool": tool}


@dataclass(frozen=True)
class Permits:
    """What this host lets a process of this user have, asked before a run (None: permitted,
    else why not, on one line)."""

    fifo: str | None
    mlock: str | None
    pin: str | None

    def refusals(self) -> list[str]:
        """What the host refuses, one phrase each."""
        return [why for why in (self.fifo, self.mlock, self.pin) if why is not None]


def _capability(bit: int) -> bool:
    """Whether this process holds capability ``bit`` (``/proc/self/status``, CapEff)."""
    try:
        status = Path("/proc/self/status").read_text()
    except OSError:
        return False
    found = re.search(r"^CapEff:\s*([0-9a-f]+)", status, re.M)
    return bool(found) and bool(int(found.group(1), 16) >> bit & 1)


def _try_fifo(priority: int) -> str | None:
    """None if a thread of this process may take SCHED_FIFO at ``priority``, else why not
    (tried on a thread of its own, which then ends: the process is unchanged)."""
    result: list[str | None] = []

    def attempt() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
            result.append(None)
        except (OSError, AttributeError) as exc:
            result.append(f"SCHED_FIFO priority {priority} ({getattr(exc, 'strerror', exc)}: "
                          "needs root, CAP_SYS_NICE or rtprio in /etc/security/limits.conf)")

    worker = threading.Thread(target=attempt, name="fifo-probe")
    worker.start()
    worker.join()
    return result[0]


def permits(priority: int, cpu: int) -> Permits:
    """Ask the host, before a run, for SCHED_FIFO at ``priority``, locked memory and the
    processor ``cpu``."""
    soft, _ = resource.getrlimit(resource.RLIMIT_MEMLOCK)
    mlock = None
    if soft != resource.RLIM_INFINITY and not _capability(14):  # CAP_IPC_LOCK
        mlock = (f"memory locking beyond {soft // 1024} KiB (ulimit -l; needs root, "
                 "CAP_IPC_LOCK or memlock in /etc/security/limits.conf)")
    pin = None if cpu in os.sched_getaffinity(0) else f"processor {cpu} (not in this process's set)"
    return Permits(_try_fifo(priority), mlock, pin)
