"""The time unit of a recording, by evidence: its spacing and a plausible heartbeat.

A file that states its time unit (a CSV header ``t_ms``, a MATLAB ``time_units``, times made
from a sample rate) is read as it says. One that does not is read in seconds, and the reading is
checked against two facts of heart motion, whatever the rate:

- its strongest periodic component, the highest peak of the motion's spectrum that repeats at
  least :data:`MIN_CYCLES` times in the recording, lies between breathing and the fastest
  heartbeat, :data:`MOTION_BAND` (6 breaths/min to 250 beats/min, the heart-rate
  range of ``rhmpc data --bpm``);
- its sample rate is one an instrument of heart motion delivers, at most :data:`MAX_RATE`
  (sonomicrometry 257 Hz in Tuna et al. 2013, trackers and cameras up to 1 kHz).

When the reading in seconds fails the first and a reading in milliseconds or microseconds
passes both, the times are in that unit; when none does and the times are the numbers 0, 1, 2,
… (or any steps of exactly 1), they count frames. Either way the file is refused in one line
that says how to state the unit (:func:`check_time_unit`). A recording whose spectrum shows no
peak that repeats enough (a short or aperiodic one) keeps its reading in seconds.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from rhmpc.sim.recordings.recorded import RecordedMotion, RecordingError

#: Frequencies of heart motion [Hz]: 6 breaths/min to 250 beats/min.
MOTION_BAND = (0.1, 250.0 / 60.0)
#: The most samples per second of a heart-motion instrument [Hz].
MAX_RATE = 10_000.0
#: A component counts when the recording holds at least this many of its periods.
MIN_CYCLES = 3
#: The most samples the spectrum is taken over (the recording's first ones).
MAX_SAMPLES = 1 << 16
#: The units a file's times may be in besides seconds, and their length [s].
OTHER_UNITS = {"ms": 1e-3, "us": 1e-6}
#: Heart rates [Hz]: 20–250 beats/min (``rhmpc data --bpm``).
HEART_BAND = (20.0 / 60.0, 250.0 / 60.0)
#: How each format states a time unit.
STATE_UNIT = {".csv": "a CSV header t_{unit}", ".txt": "a CSV header t_{unit}",
              ".mat": "a MATLAB variable time_units = '{unit}'"}


def strongest_frequency(rec: RecordedMotion) -> float | None:
    """f₀, the frequency of the highest peak of the motion's power spectrum [cycles per unit
    of ``rec.t``] among those with at least :data:`MIN_CYCLES` periods in the recording; None
    when there is none (too few samples, no motion).

    The spectrum is the sum over the axes of the squared magnitude of the FFT of the first
    :data:`MAX_SAMPLES` samples, each axis clipped to its 1st–99th percentiles (outliers do not
    decide it), interpolated across gaps onto a uniform grid, its linear trend removed and a
    Hann window applied."""
    n = min(rec.t.size, MAX_SAMPLES)
    if n < 4 * MIN_CYCLES:
        return None
    t = rec.t[:n]
    period = (t[-1] - t[0]) / (n - 1)
    grid = t[0] + period * np.arange(n)
    z = rec.z[:n]
    ok = np.all(np.isfinite(z), axis=1)
    if ok.sum() < 4 * MIN_CYCLES:
        return None
    power = np.zeros(n // 2 + 1)
    window = np.hanning(n)
    for axis in range(z.shape[1]):
        low, high = np.quantile(z[ok, axis], [0.01, 0.99])  # outliers do not decide it
        y = np.interp(grid, t[ok], np.clip(z[ok, axis], low, high))
        y = y - np.polyval(np.polyfit(grid - grid[0], y, 1), grid - grid[0])  # no drift
        power += np.abs(np.fft.rfft(y * window)) ** 2
    f = np.fft.rfftfreq(n, period)
    usable = f >= MIN_CYCLES / (period * n)
    if not usable.any() or not np.any(power[usable] > 0):
        return None
    return float(f[usable][np.argmax(power[usable])])


def _plausible(f0: float, rate: float, unit: float) -> bool:
    """Whether a recording of f₀ [cycles per time unit] at ``rate`` [samples per unit] is heart
    motion when the unit lasts ``unit`` seconds."""
    return MOTION_BAND[0] <= f0 / unit <= MOTION_BAND[1] and rate / unit <= MAX_RATE


def _per_minute(f: float) -> str:
    return f"{60.0 * f:.3g}/min"


def _fix(rec: RecordedMotion, unit: str) -> str:
    """How to state ``unit`` in ``rec``'s format."""
    suffix = Path(rec.name.split(":p")[0]).suffix.lower()
    how = STATE_UNIT.get(suffix)
    return (f"state the unit ({how.format(unit=unit)}) or write the times in seconds"
            if how else "write the times in seconds")


def check_time_unit(rec: RecordedMotion) -> None:
    """Refuse ``rec``, read in seconds, when the evidence says its times are in another unit
    or count frames (module docstring); nothing when its file stated the unit
    (``rec.time_unit``).

    Raises
    ------
    RecordingError
        Naming the file, what the times look like, the rate and heartbeat each reading gives,
        and how to state the unit.
    """
    if rec.time_unit is not None or rec.t.size < 2:
        return
    f0 = strongest_frequency(rec)
    rate = rec.sample_rate
    if f0 is None or _plausible(f0, rate, 1.0):
        return
    as_seconds = (f"read in seconds it is sampled at {rate:.4g} Hz and its motion repeats "
                  f"every {1 / f0:.3g} s ({_per_minute(f0)}), which no heart does")
    for unit, length in OTHER_UNITS.items():
        if _plausible(f0, rate, length):
            name = "milliseconds" if unit == "ms" else "microseconds"
            raise RecordingError(
                f"{rec.name}: the times look like {name}: {as_seconds}; read in {unit} it is "
                f"sampled at {rate / length:.4g} Hz and beats at {_per_minute(f0 / length)}: "
                f"{_fix(rec, unit)}")
    steps = np.diff(rec.t)
    if np.all(rec.t == np.round(rec.t)) and np.median(steps) == 1.0:
        low, high = (band / f0 for band in HEART_BAND)
        raise RecordingError(
            f"{rec.name}: the times look like frame numbers (steps of 1): {as_seconds}; were "
            f"it a heartbeat of 20–250/min, the frames came at {math.ceil(low):g}–"
            f"{math.floor(high):g} per second: write the times in seconds (frame / frame "
            "rate)")
