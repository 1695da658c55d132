"""Bounds from one table: the largest count, size or file a user may ask rhmpc for.

Each count a user sets (Monte Carlo trials, an MPC horizon, the samples of a recording, a
model's window) costs memory and computing in proportion to it. :data:`BOUNDS` states, per
count, what one unit costs, measured on one core (the figures and how they were measured are in
each entry's ``source``), and :meth:`Bound.check` refuses a value whose cost exceeds
:data:`MEMORY_BUDGET` or :data:`TIME_BUDGET`, naming the largest value that fits, before any
of the work starts. :data:`FILE_BYTES` bounds the size of each kind of input file
(:mod:`rhmpc.io.reader`).

The budgets are those of one command on a workstation: 2 GiB of memory, what a run may take
beside the rest of the machine (the interactive use of a laptop of 8 GiB), and a day of
computing on one core, the longest run the loop accepts (``[loop] duration``, 86 400 s of
simulated time, runs in about that).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

__all__ = ["BOUNDS", "FILE_BYTES", "MEMORY_BUDGET", "TIME_BUDGET", "Bound", "available_memory",
           "check", "largest", "size_bytes", "time_span"]

#: Memory one command may take [B]: 2 GiB.
MEMORY_BUDGET = 2 * 2**30
#: Computing one command may take on one core [s]: a day.
TIME_BUDGET = 86400.0
#: The budgets in a message.
BUDGETS = "2 GiB of memory and a day of computing"

MiB = 2**20
#: The largest file of each kind that is read [B]. A run's settings (TOML) and a sweep's
#: specification are hand-written, a few kB; a results file holds a line of about 2 kB per
#: evaluation, about 10 kB once read (128 000 evaluations in 256 MiB); a recording of 10 h at
#: 1 kHz as CSV is about 1.3 GB (its samples are bounded by ``BOUNDS["samples"]``); a model holds
#: at most half the memory budget of weights (its copy while it loads). A ROS bag is read one
#: message at a time and keeps only the samples of the topic asked for (bounded as a
#: recording's), so its size bounds the time it takes to read, not memory: its topics beside
#: the tracker's (cameras) make it large, and 256 GiB read at 100 MB/s take about 45 min; its
#: metadata (``metadata.yaml``, a few kB) is bounded as a settings file.
FILE_BYTES: dict[str, int] = {
    "file": 1024 * MiB,
    "config": 4 * MiB,
    "tune spec": 4 * MiB,
    "results file": 256 * MiB,
    "recording": 2048 * MiB,
    "bag": 256 * 1024 * MiB,
    "bag metadata": 4 * MiB,
    "model": 1024 * MiB,
    "model header": 4 * MiB,
    "annotation file": 256 * MiB,
    "trace": 4096 * MiB,
    "C source": 64 * MiB,
    "library": 512 * MiB,
}


def size_bytes(n: float) -> str:
    """A memory size in B, kB, MB, GB, TB, PB or EB."""
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1000:
            return f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:.3g} EB"


def time_span(seconds: float) -> str:
    """A time span in s, min, h, days or years."""
    for unit, size in (("years", 365.25 * 86400), ("days", 86400), ("h", 3600), ("min", 60)):
        if seconds >= size:
            return f"{seconds / size:.3g} {unit}"
    return f"{seconds:.2g} s"


@dataclass(frozen=True)
class Bound:
    """What one unit of a count costs, and the largest count that fits.

    Attributes
    ----------
    what : str
        The count, as a message names it (``"Monte Carlo trials"``).
    bytes_each : float
        Memory per unit [B] (an upper estimate: the largest measured, rounded up).
    seconds_each : float
        Computing per unit on one core [s] (likewise).
    cap : float
        The largest value whatever the budgets (a specification's), or ∞.
    source : str
        How the costs were measured.
    """

    what: str
    bytes_each: float
    seconds_each: float
    cap: float = math.inf
    source: str = ""

    def largest(self, memory_scale: float = 1.0, time_scale: float = 1.0,
                workers: int = 1) -> int:
        """The largest count whose cost fits both budgets: a unit costs ``bytes_each`` ×
        ``memory_scale`` of memory and ``seconds_each`` × ``time_scale`` of computing, spread
        over ``workers`` cores."""
        fits = [self.cap]
        if self.bytes_each > 0 and memory_scale > 0:
            fits.append(MEMORY_BUDGET / (self.bytes_each * memory_scale))
        if self.seconds_each > 0 and time_scale > 0:
            fits.append(TIME_BUDGET * max(1, workers) / (self.seconds_each * time_scale))
        return max(0, math.floor(min(fits)))

    def check(self, value: float, name: str, memory_scale: float = 1.0,
              time_scale: float = 1.0, workers: int = 1) -> None:
        """Raise ``ValueError`` naming ``name``, the cost and the largest value that fits when
        ``value`` does not (scales as for :meth:`largest`)."""
        top = self.largest(memory_scale, time_scale, workers)
        if value <= top:
            return
        cost = []
        if self.bytes_each > 0 and memory_scale > 0:
            cost.append(f"about {size_bytes(value * self.bytes_each * memory_scale)} of memory")
        if self.seconds_each > 0 and time_scale > 0:
            cost.append(f"{time_span(value * self.seconds_each * time_scale / max(1, workers))}"
                        " of computing")
        need = " and ".join(cost) or "more than is allowed"
        where = "" if workers <= 1 else f" on {workers} workers"
        count = f"{int(value)}" if float(value).is_integer() else f"{value:g}"
        raise ValueError(f"{name}: {count} {self.what} would take {need}; at most {top} fit "
                         f"in {BUDGETS}{where}")


#: The bounds of every count a user sets, by name.
BOUNDS: dict[str, Bound] = {
    "window": Bound(
        "samples in a delay window", bytes_each=8.0, seconds_each=0.0,
        source="one float64 per sample and channel of the online history (memory_scale: the "
               "channels, P·d; in a fit, three copies of every training regressor: 3·m·P·d)"),
    "samples": Bound(
        "samples of a recording", bytes_each=256.0, seconds_each=0.0,
        source="a 1-kHz CSV of 10⁶ samples (39 MB): rhmpc data show peaked at 322 MB, "
               "simulate at 297 MB, against 140 MB and 150 MB for 10⁵: 150–200 B per sample, "
               "rounded up to 256 B"),
    **{f"{study} trials": Bound(
        "Monte Carlo trials", bytes_each=4096.0, seconds_each=seconds,
        source=f"rhmpc predict --study {study} --trials 1 on one core: {seconds:g} s per trial, "
               "value and predictor (time_scale: values × predictors; memory_scale: values); "
               "a task's seed, settings and results under 4 kB")
       for study, seconds in (("noise", 0.085), ("hr-step", 0.16), ("rr", 0.25),
                              ("horizon", 2.4))},
    "horizon": Bound(
        "MPC horizon steps", bytes_each=24e3, seconds_each=7e-6,
        source="rhmpc simulate --set mpc.horizon=N --set mpc.blocks=[N], 0.5 s: N = 1000 "
               "and 4000 took 206 MB and 247 MB, 6.9 s and 29.6 s; N = 100 000 took 2.2 GB: "
               "24 kB per step, 7 µs per step and tick (time_scale: the run's ticks)"),
}


def largest(name: str, memory_scale: float = 1.0, time_scale: float = 1.0,
            workers: int = 1) -> int:
    """The largest value of count ``name`` that fits (:meth:`Bound.largest`)."""
    return BOUNDS[name].largest(memory_scale, time_scale, workers)


def check(name: str, value: float, label: str | None = None, memory_scale: float = 1.0,
          time_scale: float = 1.0, workers: int = 1) -> None:
    """Refuse ``value`` of count ``name`` when it does not fit (:meth:`Bound.check`); the
    message names ``label`` (the option or setting, default ``name``)."""
    BOUNDS[name].check(value, label or name, memory_scale, time_scale, workers)


#: The memory assumed available where the system does not say [B].
FALLBACK_MEMORY = 8e9


def available_memory() -> float:
    """The memory available to a new allocation [B]: Linux's MemAvailable, else the free pages,
    else :data:`FALLBACK_MEMORY`."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except (OSError, ValueError, IndexError):
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, OSError, ValueError):
        return FALLBACK_MEMORY
