"""Bounds from one table: the largest count, size or file a user may ask rhmpc for.

Each count a user sets (Monte Carlo trials, an MPC horizon, the samples of a recording, a
model's window) costs memory and computing in proportion to it. :data:`BOUNDS` states, per
count, what one unit costs, measured on one core (the figures and how they were measured are in
each entry's ``source``), and :meth:`Bound.check` refuses a value whose cost exceeds
:data:`MEMORY_BUDGET` or :data:`TIME_BUDGET`, naming the largest value that fits, before any
of the work starts. :data:`FILE_BYTES` bounds the size of each kind of input file
(:mod:`boundary.reader`).

The budgets are those of one command on a workstation: 2 GiB of memory, what a run may take
beside the rest of the machine (the interactive use of a laptop of 8 GiB), and a day of
computing on one core, the longest run the loop accepts (``[loop] duration``, 86 400 s of
simulated time, runs in about that).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["BOUNDS", "FILE_BYTES", "MEMORY_BUDGET", "TIME_BUDGET", "Bound", "check",
           "largest", "size_bytes", "time_span"]

#: Memory one command may take [B]: 2 GiB.
MEMORY_BUDGET = 2 * 2**30
#: Computing one command may take on one core [s]: a day.
TIME_BUDGET = 86400.0

MiB = 2**20
#: The largest file of each kind that is read [B]. A run's settings (TOML) and a sweep's
#: specification are hand-written, a few kB; a results file holds a line of about 2 kB per
#: evaluation (500 000 evaluations in 1 GiB); a recording of 10 h at 1 kHz as CSV is about
#: 1.3 GB; a model holds at most ``MEMORY_BUDGET / 2`` of weights (its copy while it loads).
FILE_BYTES: dict[str, int] = {
    "file": 1024 * MiB,
    "config": 4 * MiB,
    "tune spec": 4 * MiB,
    "results file": 1024 * MiB,
    "recording": 2048 * MiB,
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

    def largest(self, scale: float = 1.0, workers: int = 1) -> int:
        """The largest count whose cost fits both budgets; ``scale`` multiplies the cost of a
        unit (e.g. the parameter values each trial runs), ``workers`` divides the time."""
        fits = [self.cap]
        if self.bytes_each > 0:
            fits.append(MEMORY_BUDGET / (self.bytes_each * scale))
        if self.seconds_each > 0:
            fits.append(TIME_BUDGET * max(1, workers) / (self.seconds_each * scale))
        return max(0, math.floor(min(fits)))

    def check(self, value: float, name: str, scale: float = 1.0, workers: int = 1) -> None:
        """Raise ``ValueError`` naming ``name``, the cost and the largest value that fits when
        ``value`` does not."""
        top = self.largest(scale, workers)
        if value <= top:
            return
        cost = []
        if self.bytes_each > 0:
            cost.append(f"about {size_bytes(value * self.bytes_each * scale)} of memory")
        if self.seconds_each > 0:
            cost.append(f"{time_span(value * self.seconds_each * scale / max(1, workers))} "
                        "of computing")
        need = " and ".join(cost) or "more than is allowed"
        raise ValueError(f"{name} {value:g}: {value:.3g} {self.what} would take {need}; at "
                         f"most {top} fit in {size_bytes(MEMORY_BUDGET)} and "
                         f"{time_span(TIME_BUDGET)}" + ("" if workers <= 1 else
                                                         f" on {workers} workers"))


#: The bounds of every count a user sets, by name.
BOUNDS: dict[str, Bound] = {}


def largest(name: str, scale: float = 1.0, workers: int = 1) -> int:
    """The largest value of count ``name`` that fits (:meth:`Bound.largest`)."""
    return BOUNDS[name].largest(scale, workers)


def check(name: str, value: float, label: str | None = None, scale: float = 1.0,
          workers: int = 1) -> None:
    """Refuse ``value`` of count ``name`` when it does not fit (:meth:`Bound.check`); the
    message names ``label`` (the option or setting, default ``name``)."""
    BOUNDS[name].check(value, label or name, scale, workers)
