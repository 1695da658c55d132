"""A recorded trajectory and the units recording files use.

:class:`RecordedMotion` is the motion source of every reader (:mod:`rhmpc.sim.recordings.text`,
:mod:`rhmpc.sim.recordings.matfile`); :class:`RecordingError` is what they raise.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.sim.heart.motion import as_time_array

#: Length units accepted in headers and flags, in metres.
LENGTH_UNITS: dict[str, float] = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "cm": 1e-2}
#: Time units accepted in headers and in a MATLAB file's ``time_units``, in seconds.
TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6}
#: Where the length unit of a recording came from: the file itself, the caller's ``units``
#: (``--units`` on the command line), or the format's documented default (CSV: millimetres).
UNIT_ORIGINS = ("file", "option", "default")
#: Axis names, in order.
AXES = ("x", "y", "z")

#: Times closer than this to a sample time count as that sample [s].
SNAP = 1e-9
#: Slowest sample rate of a heart-motion recording [Hz]: a beat (20–250 per minute) cannot be
#: followed from fewer samples, and a slower file has its times in another unit than seconds.
MIN_RATE = 1.0


def interval_steps(t: np.ndarray) -> np.ndarray:
    """k_i = max(1, round((t_{i+1} − t_i)/Δ̃)): each interval of the increasing times ``t``
    [s] in steps of their median interval Δ̃, shape (n − 1,)."""
    gaps = np.diff(np.asarray(t, dtype=float))
    return np.maximum(np.rint(gaps / np.median(gaps)), 1.0)


def nominal_rate(t: np.ndarray) -> float:
    """The nominal sample rate of the increasing times ``t`` (n ≥ 2) [Hz]: Σ k_i / (t[-1] −
    t[0]), the intervals counted in steps of the median interval (:func:`interval_steps`)."""
    return float(np.sum(interval_steps(t)) / (t[-1] - t[0]))


class RecordingError(ValueError):
    """A recording file is missing, unreadable or malformed; the message names file and line."""


class RecordedMotion:
    """A recorded trajectory, linearly interpolated between samples.

    position(t) = p_k + (t − t_k)/(t_{k+1} − t_k)·(p_{k+1} − p_k) for t_k ≤ t ≤ t_{k+1}.
    It is NaN outside ``[t[0], t[-1] + Δ]`` (the last sample holds for its period Δ) and on any
    interval touching a missing sample.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Strictly increasing sample times [s].
    z : ndarray, shape (n, dim)
        Positions [m]; NaN marks dropouts.
    name : str
        Where it came from (shown by the CLI).
    units : str, optional
        The length unit the file was read in (a key of :data:`LENGTH_UNITS`), if known.
    units_origin : str, optional
        Where that unit came from, one of :data:`UNIT_ORIGINS`.
    time_unit : str, optional
        The time unit the file stated (a key of :data:`TIME_UNITS`; ``"s"`` for times made
        from a stated sample rate), or None: read in seconds without the file saying so
        (:mod:`rhmpc.sim.recordings.timebase` checks that reading).
    """

    def __init__(self, t: np.ndarray, z: np.ndarray, name: str = "recording",
                 units: str | None = None, units_origin: str | None = None,
                 time_unit: str | None = None) -> None:
        self.t = np.asarray(t, dtype=float)
        self.z = np.asarray(z, dtype=float).reshape(self.t.size, -1)
        self.dim = self.z.shape[1]
        self.name = name
        self.units, self.units_origin = units, units_origin
        self.time_unit = time_unit
        self._missing = ~np.all(np.isfinite(self.z), axis=1)

    @property
    def duration(self) -> float:
        """n samples at the nominal rate f last n/f [s]: t[-1] − t[0] + Δ, the last sample
        holding for its period Δ = 1/f, as a video frame does (750 frames at 25 Hz: 30 s)."""
        return float(self.t[-1] - self.t[0]) + self.period

    @property
    def period(self) -> float:
        """Δ = 1/f, the nominal sample period [s] (:attr:`sample_rate`; 0 for one sample)."""
        return 1.0 / self.sample_rate if self.t.size > 1 else 0.0

    @property
    def sample_rate(self) -> float:
        """The nominal sample rate [Hz]: intervals counted in steps of the median interval Δ̃,
        k_i = max(1, round((t_{i+1} − t_i)/Δ̃)), and rate = Σ k_i / (t[-1] − t[0]).

        Timestamps written with few decimals (1/30 s as 0.033 and 0.034) give the true rate,
        not 1/Δ̃; a gap of about k intervals counts as k.
        """
        return nominal_rate(self.t)

    @property
    def missing(self) -> np.ndarray:
        """Per sample, whether any coordinate is missing (NaN), shape (n,)."""
        return self._missing.copy()

    def with_samples(self, t: np.ndarray, z: np.ndarray, name: str | None = None
                     ) -> RecordedMotion:
        """Other samples with this recording's name and units (``name`` replaces the name)."""
        return RecordedMotion(t, z, self.name if name is None else name, self.units,
                              self.units_origin, self.time_unit)

    def starting_at(self, t0: float = 0.0) -> RecordedMotion:
        """The same recording with its time axis shifted so that it starts at ``t0`` [s]."""
        return self.with_samples(self.t - self.t[0] + t0, self.z)

    def position(self, t: float | np.ndarray) -> np.ndarray:
        """p(t) [m]: shape (dim,) for a float, (n, dim) for an array; NaN where no data."""
        ts, scalar = as_time_array(t)
        k = np.clip(np.searchsorted(self.t, ts, side="right") - 1, 0, self.t.size - 2)
        t0, t1 = self.t[k], self.t[k + 1]
        w = ((ts - t0) / (t1 - t0))[:, None]
        with np.errstate(invalid="ignore"):
            out = (1.0 - w) * self.z[k] + w * self.z[k + 1]
        # A time within SNAP of a sample is that sample (resampling at the file's own rate).
        at0, at1 = np.abs(ts - t0) <= SNAP, np.abs(ts - t1) <= SNAP
        out = np.where(at0[:, None], self.z[k], np.where(at1[:, None], self.z[k + 1], out))
        last = (ts > self.t[-1] + SNAP) & (ts <= self.t[-1] + self.period + SNAP)
        out[last] = self.z[-1]  # the last sample holds for its period
        bad = (ts < self.t[0] - SNAP) | (ts > self.t[-1] + SNAP)
        bad |= self._missing[k] & ~at1
        bad |= self._missing[k + 1] & ~at0
        bad = np.where(last, self._missing[-1], bad)
        out[bad] = np.nan
        return out[0] if scalar else out


def check_file(path: Path) -> None:
    """Raise :class:`RecordingError` unless ``path`` is a regular file the one reader opens
    (:func:`rhmpc.io.open_input`: not a folder, a FIFO or a device; within its size bound)."""
    try:
        io.open_input(path, "recording").close()
    except io.FileError as exc:
        raise RecordingError(str(exc)) from None


def check_rate(rec: RecordedMotion) -> None:
    """Raise :class:`RecordingError` when ``rec`` is sampled slower than :data:`MIN_RATE`,
    naming the time unit that would make it plausible."""
    rate = rec.sample_rate
    if rate >= MIN_RATE:
        return
    unit = "ms" if rate * 1e3 >= MIN_RATE else "us"
    raise RecordingError(
        f"{rec.name}: one sample every {1 / rate:.3g} s ({rate:.3g} Hz) cannot follow a "
        f"heartbeat (at least {MIN_RATE:g} Hz is needed); if the times are in "
        f"{'milliseconds' if unit == 'ms' else 'microseconds'}, say so (a CSV header t_{unit}, "
        f"a MATLAB variable time_units = '{unit}') or store an NPZ file's 't' in seconds")


def fail(path: Path, problem: str, line: int | None = None) -> RecordingError:
    where = f"{path}, line {line}" if line is not None else f"{path}"
    return RecordingError(f"{where}: {problem}")
