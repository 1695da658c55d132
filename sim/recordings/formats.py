"""Every format a recording comes in, read by one function: CSV, NPZ and MATLAB files by their
suffix, ROS bags by theirs or as a rosbag2 folder (:mod:`rhmpc.sim.recordings.bagfile`)."""

from __future__ import annotations

from pathlib import Path

from rhmpc.sim.recordings.bagfile import check_bag, is_bag, read_bag
from rhmpc.sim.recordings.csvfile import read_csv
from rhmpc.sim.recordings.matfile import load_mat
from rhmpc.sim.recordings.recorded import RecordedMotion, RecordingError, check_file
from rhmpc.sim.recordings.text import read_npz

#: The suffixes read, for a message.
SUFFIXES = ".csv, .npz, .mat, or a ROS bag (.bag, .mcap, .db3, or a rosbag2 folder)"


def found(path: str | Path) -> bool:
    """Whether ``path`` is there as a recording may be: a file, or a folder (a rosbag2 bag)."""
    path = Path(path)
    return path.is_file() or path.is_dir()


def check_source(path: str | Path) -> None:
    """Raise :class:`RecordingError` unless ``path`` is a recording the one reader opens: a
    regular file within its bound, or a ROS bag (:func:`rhmpc.sim.recordings.bagfile.check_bag`)."""
    path = Path(path)
    if is_bag(path):
        check_bag(path)
    else:
        check_file(path)


def read_any(path: str | Path, units: str | None = None, var: str | None = None, rows=None,
             cols=None, rate: float | None = None, topic: str | None = None,
             frame: str | None = None, points: bool = False) -> RecordedMotion:
    """The recording at ``path`` as its format reads it, unchecked as heart motion: (n, dim),
    or with ``points`` every column of a file of several tracked points, (n, 3P).

    ``var``, ``rows``, ``cols`` and ``rate`` apply to MATLAB files, ``topic`` and ``frame`` to
    ROS bags, ``units`` to all (:func:`rhmpc.sim.recordings.load_recording`); one given to
    another format is a :class:`RecordingError`.
    """
    path = Path(path)
    mat_options = any(v is not None for v in (var, rows, cols, rate))
    if is_bag(path):
        if mat_options:
            raise RecordingError(f"{path}: --var, --rows, --cols and --rate apply to .mat files")
        return read_bag(path, topic, frame, units, points)
    if topic is not None or frame is not None:
        raise RecordingError(f"{path}: --topic and --frame apply to ROS bags")
    check_file(path)
    suffix = path.suffix.lower()
    if suffix == ".mat":
        return load_mat(path, var=var, rows=rows, cols=cols, rate=rate, units=units,
                        points=points)
    if mat_options:
        raise RecordingError(f"{path}: --var, --rows, --cols and --rate apply to .mat files")
    if suffix in {".csv", ".txt"}:
        return read_csv(path, units, points=points)
    if suffix == ".npz":
        return read_npz(path, units, points=points)
    raise RecordingError(f"{path}: unsupported file type {path.suffix!r} (use {SUFFIXES})")
