"""Whether a recording looks like heart motion: its span, its outliers, its missing samples,
the gaps in its sample times.

Heart motion spans 0.5–40 mm peak to peak: a few millimetres on the epicardium, up to about
20 mm at the mitral annulus, more with breathing. A recording far outside that range was most
likely read in the wrong length unit (a millimetre file read as metres spans metres), so the
readers warn, name the unit that would make it plausible and say how to give it. They warn, and
do not refuse, because odd recordings exist (a phantom driven further than a heart moves).

Warnings are :class:`RecordingWarning`; the command line prints each on one line. Python code
can turn them into errors (``warnings.simplefilter("error", RecordingWarning)``) or silence
them like any warning.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from rhmpc.sim.recordings.gaps import find_gaps
from rhmpc.sim.recordings.recorded import LENGTH_UNITS, RecordedMotion

#: The length units a fix may name, smallest first (``µm`` is ``um``).
SUGGESTED_UNITS = ("um", "mm", "cm", "m")


class RecordingWarning(UserWarning):
    """A recording was read, but it is unlikely to be what the user meant (units, gaps)."""


@dataclass(frozen=True)
class Plausibility:
    """What a heart-motion recording is expected to look like.

    Attributes
    ----------
    min_span : float
        Smallest plausible peak-to-peak span of the motion on its widest axis [m].
    max_span : float
        Largest plausible span [m].
    quantile : float
        The span of an axis is taken from this quantile to its complement, so that a few
        outliers do not decide it [-] (0.01: the 1st to the 99th percentile).
    outlier_factor : float
        A sample farther than this many spans from its axis's median is an outlier [-].
    max_missing : float
        Largest fraction of missing samples that passes without a warning [-].
    min_seconds : float
        The span is judged only on a recording with at least this much time of complete
        samples: a shorter stretch may hold less than a beat [s].
    max_gap : float
        The longest gap in the sample times that passes without a warning [s]
        (:mod:`rhmpc.sim.recordings.gaps`): 1 s, a beat at 60 beats/min; over a longer one a
        predictor goes without a sample for a beat or more.
    """

    min_span: float = 0.5e-3
    max_span: float = 40e-3
    quantile: float = 0.01
    outlier_factor: float = 10.0
    max_missing: float = 0.5
    min_seconds: float = 2.0
    max_gap: float = 1.0

    def __post_init__(self) -> None:
        if not 0 < self.min_span < self.max_span < math.inf:
            raise ValueError("need 0 < min_span < max_span [m], got "
                             f"{self.min_span!r}, {self.max_span!r}")
        if not 0 <= self.quantile < 0.5:
            raise ValueError(f"quantile must be in [0, 0.5) [-], got {self.quantile!r}")
        if not self.outlier_factor > 1:
            raise ValueError(f"outlier_factor must be > 1 [-], got {self.outlier_factor!r}")
        if not 0 <= self.max_missing <= 1:
            raise ValueError(f"max_missing must be in [0, 1] [-], got {self.max_missing!r}")
        if not 0 <= self.min_seconds < math.inf:
            raise ValueError(f"min_seconds must be >= 0 [s], got {self.min_seconds!r}")
        if not 0 < self.max_gap < math.inf:
            raise ValueError(f"max_gap must be > 0 [s], got {self.max_gap!r}")


def robust_span(z: np.ndarray, quantile: float) -> float:
    """The largest per-axis range of the complete rows of ``z`` (n, d), from the ``quantile``
    to the 1 − ``quantile`` quantile [unit of z]; NaN without a complete row."""
    complete = z[np.all(np.isfinite(z), axis=1)]
    if not complete.size:
        return math.nan
    lo, hi = np.quantile(complete, [quantile, 1.0 - quantile], axis=0)
    return float(np.max(hi - lo))


def span_problem(rec: RecordedMotion, settings: Plausibility = Plausibility()) -> str | None:
    """Why the span of ``rec`` is implausible for heart motion, with the fix; None if it is
    plausible, or unknown (less than ``min_seconds`` of complete samples)."""
    if np.sum(~rec.missing) / rec.sample_rate < settings.min_seconds:
        return None
    span = robust_span(rec.z, settings.quantile)
    if not math.isfinite(span) or settings.min_span <= span <= settings.max_span:
        return None
    unit = rec.units or "m"
    read = {"option": f"read in {unit} as --units says",
            "file": f"read in {unit} as the file says",
            "default": f"read in {unit}, the format's default"}.get(rec.units_origin or "",
                                                                f"read in {unit}")
    text = (f"{rec.name}: the motion spans {_mm(span)} peak to peak, {read}; heart motion "
            f"spans {1e3 * settings.min_span:g}–{_mm(settings.max_span)}")
    other = _plausible_unit(span, unit, settings)
    if other is None:
        return text + ": check the data and their units"
    in_other = span * LENGTH_UNITS[other] / LENGTH_UNITS[unit]
    fix = ("correct the units the file states" if rec.units_origin == "file"
           else f"pass --units {other}")
    return (text + f". Read in {other} it would span {_mm(in_other)}: if the file is in "
            f"{_UNIT_NAMES[other]}, {fix}")


def outlier_problem(rec: RecordedMotion, settings: Plausibility = Plausibility()) -> str | None:
    """Which samples of ``rec`` lie implausibly far from the rest (more than
    ``outlier_factor`` spans from their axis's median); None if none does."""
    complete = np.all(np.isfinite(rec.z), axis=1)
    span = robust_span(rec.z, settings.quantile)
    if not complete.any() or not math.isfinite(span):
        return None
    z = rec.z[complete]
    with np.errstate(over="ignore", invalid="ignore"):
        distance = np.max(np.abs(z - np.median(z, axis=0)), axis=1)
    far = np.flatnonzero(distance > settings.outlier_factor * max(span, settings.min_span))
    if not far.size:
        return None
    worst = far[np.argmax(distance[far])]
    index = int(np.flatnonzero(complete)[worst])
    return (f"{rec.name}: {far.size} sample(s) lie more than {settings.outlier_factor:g} × the "
            f"motion's span ({_mm(span)}) from the rest, the farthest {_mm(distance[worst])} "
            f"away (sample {index + 1}, t = {rec.t[index]:.6g} s): outliers or corrupt values?")


def missing_problem(rec: RecordedMotion, settings: Plausibility = Plausibility()) -> str | None:
    """How much of ``rec`` is missing, when more than ``max_missing`` of its samples are."""
    missing = rec.missing
    fraction = float(np.mean(missing))
    if fraction <= settings.max_missing:
        return None
    complete = int(np.sum(~missing))
    seconds = complete / rec.sample_rate
    return (f"{rec.name}: {100 * fraction:.1f} % of the samples are missing ({complete} of "
            f"{missing.size} complete, about {seconds:.3g} s of data): what is computed from it "
            "rests on those")


def gap_problem(rec: RecordedMotion, settings: Plausibility = Plausibility()) -> str | None:
    """The gaps of at least ``max_gap`` in the sample times of ``rec``
    (:func:`rhmpc.sim.recordings.gaps.find_gaps`), when there are any."""
    gaps = find_gaps(rec.t, settings.max_gap)
    if not gaps.count:
        return None
    return (f"{rec.name}: {gaps.count} gap(s) of {settings.max_gap:g} s or more in the sample "
            f"times, {gaps.seconds:.4g} s in all; the longest {gaps.longest:.4g} s from "
            f"t = {gaps.at:.4g} s: nothing was measured there (rhmpc data show lists every "
            "gap)")


def check_recording(rec: RecordedMotion, settings: Plausibility = Plausibility(), *,
                    span: bool = True, missing: bool = True, gaps: bool = True) -> list[str]:
    """Warn (:class:`RecordingWarning`) about what makes ``rec`` implausible as heart motion:
    its span (``span``: also its outliers), its missing samples (``missing``), the gaps in its
    sample times (``gaps``).

    Returns
    -------
    list of str
        The warnings' messages, in the order they were issued.
    """
    problems = []
    if span:
        problems += [span_problem(rec, settings), outlier_problem(rec, settings)]
    if missing:
        problems.append(missing_problem(rec, settings))
    if gaps:
        problems.append(gap_problem(rec, settings))
    messages = [p for p in problems if p is not None]
    for message in messages:
        warnings.warn(message, RecordingWarning, stacklevel=2)
    return messages


def _plausible_unit(span: float, unit: str, settings: Plausibility) -> str | None:
    """The unit of :data:`SUGGESTED_UNITS` other than ``unit`` in which a span of ``span``
    [m, as read in ``unit``] is plausible: millimetres if they are (the common unit), else
    the one nearest the middle of the range; or None."""
    middle = math.sqrt(settings.min_span * settings.max_span)
    scale = {u: span * LENGTH_UNITS[u] / LENGTH_UNITS[unit] for u in SUGGESTED_UNITS
             if LENGTH_UNITS[u] != LENGTH_UNITS[unit]}
    fits = [u for u, s in scale.items() if settings.min_span <= s <= settings.max_span]
    if "mm" in fits:
        return "mm"
    return min(fits, key=lambda u: abs(math.log(scale[u] / middle)), default=None)


#: The units' names in a sentence.
_UNIT_NAMES = {"um": "micrometres", "mm": "millimetres", "cm": "centimetres", "m": "metres"}


def _mm(value: float) -> str:
    """A length [m] in millimetres with four significant digits (no exponent below 1e6)."""
    mm = value * 1e3
    return f"{mm:.4g} mm" if abs(mm) < 1e6 else f"{mm:.3g} mm"
