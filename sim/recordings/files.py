"""Open a recording of any supported format: CSV, NPZ, MATLAB ``.mat`` or a ROS bag, and check
it as heart motion."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rhmpc.sim.recordings.formats import read_any
from rhmpc.sim.recordings.plausible import check_recording
from rhmpc.sim.recordings.points import load_points, pick_point
from rhmpc.sim.recordings.recorded import RecordedMotion, RecordingError, check_rate
from rhmpc.sim.recordings.timebase import check_time_unit


def load_recording(path: str | Path, units: str | None = None, var: str | None = None,
                   rows=None, cols=None, rate: float | None = None,
                   point: int | None = None, topic: str | None = None,
                   frame: str | None = None) -> RecordedMotion:
    """Load a heart-motion recording (CSV, NPZ, MATLAB .mat: see
    :mod:`rhmpc.sim.recordings.matfile`; or a topic of a ROS bag:
    :mod:`rhmpc.sim.recordings.bagfile`).

    Parameters
    ----------
    path : str or Path
        ``.csv`` (or ``.txt``), ``.npz`` or ``.mat`` file, or a ROS bag (a rosbag2 folder, its
        ``.mcap`` or ``.db3`` file, a ROS 1 ``.bag``).
    units : str, optional
        Length unit of the positions when the file does not state it (``"m"``, ``"mm"``,
        ``"um"``, ``"cm"``). A CSV or MAT file without units is in millimetres, a bag in
        metres (ROS's unit); an NPZ file needs its units, from the file or from here.
    var, rows, cols, rate : optional
        For ``.mat`` files: the variable, its 0-based rows or columns holding the coordinates,
        and the sample rate [Hz] when the file has neither a time vector nor a rate
        (:func:`rhmpc.sim.recordings.matfile.load_mat`).
    point : int, optional
        In a file of several tracked points, the point to read, from 1
        (:mod:`rhmpc.sim.recordings.points`); such a file needs it.
    topic, frame : str, optional
        For a ROS bag: the POI's topic, and the child frame of a tf topic
        (:func:`rhmpc.sim.recordings.bagfile.read_bag`).

    Returns
    -------
    RecordedMotion
        Positions in metres, times in seconds; missing samples are NaN.

    Raises
    ------
    RecordingError
        Naming the file, the line (or the topic) and the problem; also when its times, read in
        seconds because the file states no unit, look like milliseconds or frame numbers
        (:mod:`rhmpc.sim.recordings.timebase`).

    Warns
    -----
    RecordingWarning
        When the recording is implausible as heart motion: a span outside 0.5–40 mm (with the
        unit that would fit), outliers, more than half of its samples missing, or a gap in its
        sample times of a second or more (:mod:`rhmpc.sim.recordings.plausible`); for a bag,
        also when messages were reordered or left out by their stamps
        (:mod:`rhmpc.sim.recordings.bagstamps`).
    """
    path = Path(path)
    if point is not None:
        points = load_points(path, units, var, rows, cols, rate, topic, frame)
        return pick_point(path, points, point)
    rec = read_any(path, units, var, rows, cols, rate, topic, frame)
    if not np.any(np.all(np.isfinite(rec.z), axis=1)):
        raise RecordingError(f"{path}: no complete sample (all positions missing)")
    check_rate(rec)
    check_time_unit(rec)
    check_recording(rec)
    return rec
