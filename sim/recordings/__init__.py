"""Heart-motion recordings users bring: CSV, NPZ and MATLAB files, read and written.

==============  =================================================================
``recorded``    :class:`RecordedMotion` (a recording as a motion source),
                :class:`RecordingError`, the unit tables
``csvfile``     CSV, read in blocks
``text``        NPZ, and writing: :func:`save_recording`, :func:`export_source`
``matfile``     MATLAB ``.mat`` v5 and v7.3 (HDF5), only the variables a recording needs
``timebase``    the time unit by evidence: times in milliseconds or frame numbers refused
``points``      :func:`load_points`: files of several tracked points, point by point
``files``       :func:`load_recording`: any of them, by suffix
``plausible``   :class:`RecordingWarning` on a recording unlikely to be heart motion as read
                (its span, outliers, missing samples): :class:`Plausibility`
==============  =================================================================
"""

from rhmpc.sim.recordings.files import load_recording
from rhmpc.sim.recordings.matfile import load_mat, parse_indices
from rhmpc.sim.recordings.plausible import Plausibility, RecordingWarning, check_recording
from rhmpc.sim.recordings.points import load_points, on_grid, training_series
from rhmpc.sim.recordings.recorded import (
    LENGTH_UNITS,
    TIME_UNITS,
    RecordedMotion,
    RecordingError,
)
from rhmpc.sim.recordings.text import export_source, save_recording

__all__ = [
    "LENGTH_UNITS", "TIME_UNITS", "Plausibility", "RecordedMotion", "RecordingError",
    "RecordingWarning", "check_recording", "export_source", "load_mat", "load_points",
    "load_recording", "on_grid", "parse_indices", "save_recording", "training_series",
]
