"""Open a recording of any supported format: CSV, NPZ or MATLAB ``.mat``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rhmpc.sim.recordings.csvfile import read_csv
from rhmpc.sim.recordings.matfile import load_mat
from rhmpc.sim.recordings.plausible import check_recording
from rhmpc.sim.recordings.points import load_points, pick_point
from rhmpc.sim.recordings.recorded import RecordedMotion, RecordingError, check_file, check_rate
from rhmpc.sim.recordings.text import read_npz
from rhmpc.sim.recordings.timebase import check_time_unit


def load_recording(path: str | Path, units: str | None = None, var: str | None = None,
                   rows=None, cols=None, rate: float | None = None,
                   point: int | None = None) -> RecordedMotion:
    """Load a heart-motion recording (CSV, NPZ, or MATLAB .mat: see
    :mod:`rhmpc.sim.recordings.matfile`).

    Parameters
    ----------
    path : str or Path
        ``.csv`` (or ``.txt``), ``.npz`` or ``.mat`` file.
    units : str, optional
        Length unit of the positions when the file does not state it (``"m"``, ``"mm"``,
        ``"um"``, ``"cm"``). A CSV without units is in millimetres; an NPZ or MAT file needs
        its units, from the file or from here.
    var, rows, cols, rate : optional
        For ``.mat`` files: the variable, its 0-based rows or columns holding the coordinates,
        and the sample rate [Hz] when the file has neither a time vector nor a rate
        (:func:`rhmpc.sim.recordings.matfile.load_mat`).
    point : int, optional
        In a file of several tracked points, the point to read, from 1
        (:mod:`rhmpc.sim.recordings.points`); such a file needs it.

    Returns
    -------
    RecordedMotion
        Positions in metres, times in seconds; missing samples are NaN.

    Raises
    ------
    RecordingError
        Naming the file, the line and the problem; also when its times, read in seconds
        because the file states no unit, look like milliseconds or frame numbers
        (:mod:`rhmpc.sim.recordings.timebase`).

    Warns
    -----
    RecordingWarning
        When the recording is implausible as heart motion: a span outside 0.5–40 mm (with the
        unit that would fit), outliers, or more than half of its samples missing
        (:mod:`rhmpc.sim.recordings.plausible`).
    """
    path = Path(path)
    if point is not None:
        return pick_point(path, load_points(path, units, var, rows, cols, rate), point)
    check_file(path)
    suffix = path.suffix.lower()
    if suffix == ".mat":
        rec = load_mat(path, var=var, rows=rows, cols=cols, rate=rate, units=units)
    elif var is not None or rows is not None or cols is not None or rate is not None:
        raise RecordingError(f"{path}: --var, --rows, --cols and --rate apply to .mat files")
    elif suffix in {".csv", ".txt"}:
        rec = read_csv(path, units)
    elif suffix == ".npz":
        rec = read_npz(path, units)
    else:
        raise RecordingError(f"{path}: unsupported file type {path.suffix!r} "
                             "(use .csv, .npz or .mat)")
    if not np.any(np.all(np.isfinite(rec.z), axis=1)):
        raise RecordingError(f"{path}: no complete sample (all positions missing)")
    check_rate(rec)
    check_time_unit(rec)
    check_recording(rec)
    return rec
