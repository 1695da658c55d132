"""Gaps in a recording's sample times: intervals in which one sample or more was not recorded.

Each interval t_{i+1} − t_i counts k_i = max(1, round((t_{i+1} − t_i)/Δ̃)) nominal periods, Δ̃
the median interval (the rule of :attr:`rhmpc.sim.recordings.RecordedMotion.sample_rate`); an
interval of k_i ≥ 2 is a gap, with k_i − 1 samples missing. Timestamps jittered by less than
half a period are no gap; a dropped frame is one.

A gap is not a missing sample (a NaN row the file holds): nothing at all was written for it.
``rhmpc data show`` lists both; a run warns about gaps of at least
:attr:`rhmpc.sim.recordings.Plausibility.max_gap` (:mod:`rhmpc.sim.recordings.plausible`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from rhmpc.sim.recordings.recorded import interval_steps


@dataclass(frozen=True)
class Gaps:
    """The gaps of a recording's sample times.

    Attributes
    ----------
    count : int
        How many intervals are gaps.
    missing : int
        Samples missing in them, Σ (k_i − 1) [-].
    seconds : float
        Their length in all, Σ (t_{i+1} − t_i) over the gaps [s].
    longest : float
        The longest gap's interval [s] (0 without gaps).
    at : float
        Where the longest starts, the time of the sample before it from the first sample [s].
    """

    count: int = 0
    missing: int = 0
    seconds: float = 0.0
    longest: float = 0.0
    at: float = 0.0

    def as_dict(self) -> dict:
        """The fields, for a JSON document (seconds rounded to the microsecond)."""
        return {k: round(v, 6) if isinstance(v, float) else v for k, v in asdict(self).items()}

    def text(self) -> str:
        """``none``, or the count, their length and the longest in words."""
        if not self.count:
            return "none"
        return (f"{self.count} ({self.seconds:.4g} s in all, about {self.missing} samples "
                f"missing); the longest {self.longest:.4g} s from t = {self.at:.4g} s")


def find_gaps(t: np.ndarray, min_length: float = 0.0) -> Gaps:
    """The gaps of the increasing sample times ``t`` [s] (module docstring) that last at least
    ``min_length`` [s]."""
    t = np.asarray(t, dtype=float)
    if t.size < 3:
        return Gaps()
    steps = interval_steps(t)
    intervals = np.diff(t)
    gap = (steps >= 2) & (intervals >= min_length)
    if not gap.any():
        return Gaps()
    where = np.flatnonzero(gap)
    worst = where[np.argmax(intervals[where])]
    return Gaps(count=int(where.size), missing=int(np.sum(steps[where] - 1)),
                seconds=float(np.sum(intervals[where])), longest=float(intervals[worst]),
                at=float(t[worst] - t[0]))


def coverage(rec, start: float, duration: float) -> dict:
    """What of ``rec`` (a :class:`rhmpc.sim.recordings.RecordedMotion`) between ``start`` and
    ``start + duration`` [s] was recorded: the fraction of its samples missing (NaN) and the
    gaps between them (:func:`find_gaps`, as :meth:`Gaps.as_dict`)."""
    inside = (rec.t >= start) & (rec.t <= start + duration)
    return {"missing_fraction": round(float(np.mean(rec.missing[inside])), 5),
            "gaps": find_gaps(rec.t[inside]).as_dict()}


def coverage_lines(row: dict) -> list[str]:
    """``data show``'s lines for :func:`coverage`'s entries of ``row``: the missing samples
    (when any) and the gaps (when known)."""
    lines = []
    if row.get("missing_fraction"):
        lines.append(f"  missing samples   {100 * row['missing_fraction']:.2f} %")
    if "gaps" in row:
        lines.append(f"  gaps              {Gaps(**row['gaps']).text()}")
    return lines
