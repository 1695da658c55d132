"""Recordings of several tracked points: each point's trajectory as a recording of its own.

Video tracking of the heart surface follows several points at once (four is common), and
files keep them side by side, three coordinates per point:

===========  =========================================================================
CSV          header ``t,x1,y1,z1,x2,y2,z2,…`` (unit suffixes as in a one-point file)
NPZ          ``position`` of shape (n, P, 3), or (n, 3P) with x1, y1, z1, x2, …
MAT          a 3P × n (or n × 3P) matrix, e.g. 12 × N for four points: x1, y1, z1, x2, …
             along its shorter axis
ROS bag      a ``geometry_msgs/PoseArray`` or ``visualization_msgs/MarkerArray`` topic
             (:mod:`rhmpc.sim.recordings.bagmsgs`)
===========  =========================================================================

Points are numbered from 1, in the file's order. A one-point file is a file of one point.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from rhmpc.sim.recordings.formats import read_any
from rhmpc.sim.recordings.plausible import check_recording
from rhmpc.sim.recordings.recorded import RecordedMotion, RecordingError, check_rate
from rhmpc.sim.recordings.timebase import check_time_unit


def load_points(path: str | Path, units: str | None = None, var: str | None = None,
                rows=None, cols=None, rate: float | None = None, topic: str | None = None,
                frame: str | None = None) -> list[RecordedMotion]:
    """Every tracked point of a recording, in the file's order (module docstring).

    Parameters
    ----------
    path : str or Path
        ``.csv``/``.txt``, ``.npz``, ``.mat`` or a ROS bag.
    units, var, rows, cols, rate, topic, frame : optional
        As for :func:`rhmpc.sim.recordings.load_recording`; ``rows``/``cols`` select one point.

    Returns
    -------
    list of RecordedMotion
        One per point (a one-point file gives a list of one), positions in metres; each named
        ``FILE:pK`` when the file holds several.

    Raises
    ------
    RecordingError
        Naming the file and the problem, also when a point has no complete sample.

    Warns
    -----
    RecordingWarning
        When the file is implausible as heart motion (:mod:`rhmpc.sim.recordings.plausible`): once
        for its span, and for each point with more than half of its samples missing.
    """
    path = Path(path)
    wide = read_any(path, units, var, rows, cols, rate, topic, frame, points=True)
    check_rate(wide)
    check_time_unit(wide)
    if wide.dim <= 3:
        recordings = [wide]
    else:
        recordings = [wide.with_samples(wide.t, wide.z[:, 3 * k:3 * k + 3], f"{path}:p{k + 1}")
                      for k in range(wide.dim // 3)]
    for k, rec in enumerate(recordings):
        if not np.any(np.all(np.isfinite(rec.z), axis=1)):
            where = f"point {k + 1}" if len(recordings) > 1 else "the recording"
            raise RecordingError(f"{path}: {where} has no complete sample (all missing)")
    check_recording(wide, missing=False)  # the units once per file, the gaps per point
    for rec in recordings:
        check_recording(rec, span=False, gaps=False)
    return recordings


def pick_point(path: str | Path, recordings: list[RecordedMotion], point: int) -> RecordedMotion:
    """Point ``point`` (from 1) of ``recordings``; a ``RecordingError`` names the valid range."""
    if isinstance(point, bool) or not isinstance(point, int | np.integer) \
            or not 1 <= point <= len(recordings):
        raise RecordingError(f"{path}: no point {point!r}; the file holds "
                             f"{len(recordings)} (point = 1…{len(recordings)})")
    return recordings[int(point) - 1]


def load_poi(path: str | Path, point: int, **read) -> tuple[RecordedMotion, np.ndarray | None]:
    """Point ``point`` (from 1) of a recording, and the other points' positions on its samples,
    (n, P − 1, d) [m] in file order, or None for a file of one point. ``read``: the options of
    :func:`load_points`."""
    points = load_points(path, **read)
    rec = pick_point(path, points, point)
    rest = [p.z for k, p in enumerate(points, 1) if k != point]
    return rec, (np.stack(rest, axis=1) if rest else None)


def on_grid(t: np.ndarray, z: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Samples on the grid t₀ + jΔ: a gap in the timestamps becomes missing samples.

    Returns the grid's times (m,) and positions (m, d) with NaN rows in the gaps. Timestamps
    too irregular to round to distinct grid slots are kept as they are, one slot each.
    """
    slot = np.rint((t - t[0]) / period).astype(np.int64)
    if slot.size > 1 and np.any(np.diff(slot) < 1):
        return t, z
    grid = np.full((int(slot[-1]) + 1, z.shape[1]), np.nan)
    grid[slot] = z
    return t[0] + period * np.arange(grid.shape[0]), grid


def training_series(files, poi: int | None, read: dict, period: float) -> list[np.ndarray]:
    """The recordings to fit on (``--train``): each (T, P, d) [m] on its grid (:func:`on_grid`),
    point ``poi`` (from 1; default the first) first, then the others in file order. Their
    sample period must be ``period`` [s] (1 %): a model runs at the period it was fitted at.

    Raises
    ------
    RecordingError
        A file that cannot be read, lacks the point, or is sampled at another rate.
    """
    out = []
    for f in files:
        rec, others = load_poi(f, 1 if poi is None else poi, **read)
        if not math.isclose(rec.period, period, rel_tol=0.01):
            raise RecordingError(f"{f}: sampled every {1e3 * rec.period:.4g} ms, the scored "
                                 f"recording every {1e3 * period:.4g} ms: fit on recordings "
                                 "of the same rate")
        stack = rec.z[:, None] if others is None else np.concatenate([rec.z[:, None], others], 1)
        _, grid = on_grid(rec.t, stack.reshape(rec.t.size, -1), rec.period)
        out.append(grid.reshape(grid.shape[0], stack.shape[1], -1))
    return out


class PointsAt:
    """The other tracked points of a recording, looked up by measurement time: what a
    multi-point predictor reads beside the POI's sample
    (:meth:`rhmpc.predictors.base.Predictor.update`).

    Parameters
    ----------
    t : ndarray (n,)
        The recording's sample times, in the run's time [s].
    others : ndarray (n, P − 1, d)
        The other points' positions at those times [m] (NaN where a point is missing).
    """

    #: Times closer than this to a sample's time count as that sample [s].
    SNAP = 1e-9

    def __init__(self, t: np.ndarray, others: np.ndarray) -> None:
        self.t = np.asarray(t, dtype=float)
        self.others = np.asarray(others, dtype=float)
        if self.others.ndim != 3 or self.others.shape[0] != self.t.size:
            raise ValueError(f"others must be (n, P - 1, d) with n = {self.t.size} samples, "
                             f"got {self.others.shape}")

    def at(self, t: float) -> np.ndarray | None:
        """The (P − 1, d) positions measured at ``t`` [m], or None when no sample was."""
        i = int(np.searchsorted(self.t, t - self.SNAP))
        if i < self.t.size and abs(self.t[i] - t) <= self.SNAP:
            return self.others[i]
        return None
