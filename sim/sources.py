"""Where a run's heart motion comes from: a named scenario or a user's recording.

This module sits above :mod:`rhmpc.sim.heart` (synthetic motion) and :mod:`rhmpc.sim.recordings`
(files), and picks between them: :func:`heart_source` for a run, :func:`export_scenario` to write a
scenario's motion to a file that :func:`rhmpc.sim.recordings.load_recording` reads back.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rhmpc.sim.heart.motion import MotionSource
from rhmpc.sim.heart.scenarios import Scenario, make_scenario
from rhmpc.sim.recordings.files import load_recording
from rhmpc.sim.recordings.points import PointsAt, load_poi
from rhmpc.sim.recordings.recorded import RecordedMotion
from rhmpc.sim.recordings.text import export_source

__all__ = ["HeartSource", "Shifted", "export_scenario", "heart_source", "read_points"]


class Shifted:
    """A motion source read from ``t0`` on, so that a run starts at t = 0."""

    def __init__(self, source: MotionSource, t0: float) -> None:
        self.source, self.t0, self.dim = source, float(t0), source.dim

    def position(self, t: float | np.ndarray) -> np.ndarray:
        return self.source.position(np.asarray(t, dtype=float) + self.t0)


@dataclass(frozen=True)
class HeartSource:
    """A run's heart motion.

    Attributes
    ----------
    motion : MotionSource
        The true motion, starting at t = 0 [m].
    label : str
        What it is, for reports (``fixed-a2-top``, ``file:rec.csv``, ``…+rr:100``).
    duration : float
        How long it is defined [s].
    origin : Scenario or RecordedMotion
        The scenario (its sensor rate, phase track) or the recording (its samples).
    others : ndarray (n, P − 1, d) or None
        In a recording of several tracked points, the other points on the POI's samples
        (``origin.t``) [m]; None otherwise.
    """

    motion: MotionSource
    label: str
    duration: float
    origin: Scenario | RecordedMotion
    others: np.ndarray | None = None

    @property
    def measured(self) -> tuple[np.ndarray, np.ndarray] | None:
        """A recording's own samples, (t [s] from 0, z (n, d) [m]); None for a scenario."""
        if not isinstance(self.origin, RecordedMotion):
            return None
        return self.origin.t - self.origin.t[0], self.origin.z

    @property
    def points(self) -> PointsAt | None:
        """The other tracked points of a recording on its samples' times from 0, or None."""
        if self.others is None:
            return None
        return PointsAt(self.origin.t - self.origin.t[0], self.others)


def heart_source(scenario: str, rng: np.random.Generator, *, data: str | None = None,
                 data_read: dict | None = None, rr: str | None = None,
                 needed: float = 0.0) -> HeartSource:
    """The motion of a recording (``data``, read with ``data_read``) or of a named scenario
    (:func:`rhmpc.sim.heart.make_scenario`, the one builder of a scenario).

    A scenario is made ``needed`` seconds long: its random processes (HRV, drift, breathing)
    are drawn over its nominal length or ``needed`` seconds, whichever is longer (past that
    they would be extrapolated polynomials), so that only a run longer than the nominal
    length changes the draws. ``rr``: a PhysioNet record whose beat annotations drive the
    heart phase.
    """
    if data is not None:
        recording, others = read_points(data, data_read or {})
        motion = Shifted(recording, recording.t[0]) if recording.t[0] != 0 else recording
        return HeartSource(motion, f"file:{Path(data).name}", recording.duration, recording,
                           others)
    overrides: dict = {"record": rr} if rr else {}
    if needed > 0:
        overrides["duration"] = needed
    made = make_scenario(scenario, rng=rng, **overrides)
    label = made.name + (f"+rr:{Path(rr).name}" if rr else "")
    return HeartSource(made.source, label, made.duration, made)


def read_points(path: str, read: dict) -> tuple[RecordedMotion, np.ndarray | None]:
    """The POI's recording (``read["point"]``, from 1, in a file of several tracked points)
    and the other points on its samples, (n, P − 1, d) [m], or None for a file of one."""
    read = dict(read)
    point = read.pop("point", None)
    if point is None:
        return load_recording(path, **read), None
    return load_poi(path, point, **read)


def export_scenario(scenario: Scenario | str, path: str | Path, duration: float | None = None,
                    rate: float | None = None, rng: np.random.Generator | None = None) -> Path:
    """Write a scenario's true motion to a CSV (s, mm) or NPZ (s, m) file.

    Parameters
    ----------
    scenario : Scenario or str
        A scenario, or a name for :func:`~rhmpc.sim.heart.make_scenario` (with ``rng``).
    path : str or Path
        ``.csv`` or ``.npz``; :func:`~rhmpc.sim.recordings.load_recording` reads it back.
    duration : float, optional
        Seconds to write [s]; default the scenario's duration.
    rate : float, optional
        Sample rate [Hz]; default the scenario's sensor rate.
    rng : numpy.random.Generator, optional
        Passed to :func:`~rhmpc.sim.heart.make_scenario` when ``scenario`` is a name.
    """
    sc = make_scenario(scenario, rng) if isinstance(scenario, str) else scenario
    duration = sc.duration if duration is None else float(duration)
    rate = sc.sensor_rate if rate is None else float(rate)
    comment = f"rhmpc scenario {sc.name}: {sc.description}; synthetic, not measured data"
    return export_source(sc.source, path, duration, rate, comment=comment)
