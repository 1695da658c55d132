"""Heart-motion recordings users bring: CSV, NPZ and MATLAB files and ROS bags, read; CSV and
NPZ written.

==============  =================================================================
``recorded``    :class:`RecordedMotion` (a recording as a motion source),
                :class:`RecordingError`, the unit tables
``csvfile``     CSV, read in blocks
``text``        NPZ, and writing: :func:`save_recording`, :func:`export_source`
``matfile``     MATLAB ``.mat`` v5 and v7.3 (HDF5), only the variables a recording needs
``timebase``    the time unit by evidence: times in milliseconds or frame numbers refused
``bagmsgs``     the ROS messages read (PoseStamped, PointStamped, TransformStamped,
                TFMessage, PoseArray, MarkerArray) and what each gives
``bagstamps``   a bag topic's sample times: its header stamps, not the receive times
``bagfile``     ROS bags (rosbag2 MCAP and SQLite 3, ROS 1) through the ``rosbags`` library,
                checked by the one reader's rules first: :func:`is_bag`
``bagsurvey``   :func:`survey`: a bag's topics, their rates, gaps and stamps (``data show``)
``formats``     every format, read by one function
``points``      :func:`load_points`: files of several tracked points, point by point
``files``       :func:`load_recording`: any of them, checked as heart motion
``gaps``        :func:`find_gaps`: intervals of the sample times with samples missing;
                :func:`coverage`: what of a recording was recorded
``plausible``   :class:`RecordingWarning` on a recording unlikely to be heart motion as read
                (its span, outliers, missing samples, gaps): :class:`Plausibility`
==============  =================================================================
"""

from rhmpc.sim.recordings.bagfile import is_bag
from rhmpc.sim.recordings.bagsurvey import survey, survey_lines
from rhmpc.sim.recordings.files import load_recording
from rhmpc.sim.recordings.gaps import Gaps, coverage, coverage_lines, find_gaps
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
    "LENGTH_UNITS", "TIME_UNITS", "Gaps", "Plausibility", "RecordedMotion", "RecordingError",
    "RecordingWarning", "check_recording", "coverage", "coverage_lines", "export_source",
    "find_gaps", "is_bag", "load_mat",
    "load_points", "load_recording", "on_grid", "parse_indices", "save_recording", "survey",
    "survey_lines", "training_series",
]
