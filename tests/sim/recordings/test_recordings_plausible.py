"""Plausibility of a recording as heart motion (rhmpc.sim.recordings.plausible): units, outliers,
missing samples; each a RecordingWarning that names the fix, never an error."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from rhmpc.sim.recordings import (
    Plausibility,
    RecordedMotion,
    RecordingWarning,
    check_recording,
    load_points,
    load_recording,
)

T = np.arange(0.0, 6.0, 1 / 25)
#: 5 mm of heart-like motion [mm]: 1.2 Hz heart, 0.25 Hz breathing
HEART = np.column_stack([2.5 * np.sin(2 * np.pi * 1.2 * T), 1.5 * np.cos(2 * np.pi * 1.2 * T),
                         2.0 * np.sin(2 * np.pi * 0.25 * T)])


def _csv(path: Path, z: np.ndarray, header: str = "t,x,y,z") -> Path:
    np.savetxt(path, np.column_stack([T, z]), delimiter=",", header=header, comments="",
               fmt="%.9g")
    return path


def _quiet(path: Path, **read) -> RecordedMotion:
    """Load and assert that no RecordingWarning is issued."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", RecordingWarning)
        return load_recording(path, **read)


def test_a_plausible_recording_passes_quietly(tmp_path: Path) -> None:
    rec = _quiet(_csv(tmp_path / "rec.csv", HEART))
    assert (rec.units, rec.units_origin) == ("mm", "default")


def test_millimetres_read_as_metres_name_the_fix(tmp_path: Path) -> None:
    path = _csv(tmp_path / "rec.csv", HEART)
    with pytest.warns(RecordingWarning, match=r"read in m as --units says.*in millimetres, "
                      r"pass --units mm") as caught:
        load_recording(path, units="m")
    assert len(caught) == 1 and "\n" not in str(caught[0].message)
    assert "spans 499" in str(caught[0].message)  # about 5000 mm, as read


def test_metres_read_as_the_csv_default_name_metres(tmp_path: Path) -> None:
    path = _csv(tmp_path / "rec.csv", HEART * 1e-3)
    with pytest.warns(RecordingWarning, match=r"the format's default.*pass --units m$"):
        load_recording(path)
    _quiet(path, units="m")


def test_a_header_unit_that_does_not_fit_asks_to_correct_the_file(tmp_path: Path) -> None:
    path = _csv(tmp_path / "rec.csv", HEART, header="t,x_m,y_m,z_m")
    with pytest.warns(RecordingWarning, match="as the file says.*correct the units the file "
                      "states"):
        load_recording(path)


def test_no_unit_fits_says_check_the_data(tmp_path: Path) -> None:
    path = _csv(tmp_path / "flat.csv", np.zeros_like(HEART))
    with pytest.warns(RecordingWarning, match="check the data and their units"):
        load_recording(path)


def test_an_outlier_is_named_and_does_not_decide_the_span(tmp_path: Path) -> None:
    z = HEART.copy()
    z[70] = 1e300
    path = _csv(tmp_path / "huge.csv", z)
    with pytest.warns(RecordingWarning, match=r"1 sample\(s\) lie more than 10 × .* \(sample 71, "
                      r"t = 2\.8 s\)") as caught:
        load_recording(path)
    assert len(caught) == 1  # the units are not blamed


def test_mostly_missing_is_one_warning_per_point(tmp_path: Path) -> None:
    z = np.column_stack([HEART, HEART])
    z[10:, 3:] = np.nan  # point 2: 140 of 150 samples missing
    path = _csv(tmp_path / "p.csv", z, header="t,x1,y1,z1,x2,y2,z2")
    with pytest.warns(RecordingWarning, match=r"p\.csv:p2: 93\.3 % of the samples are missing "
                      r"\(10 of 150 complete") as caught:
        load_points(path)
    assert len(caught) == 1


def test_points_warn_about_the_units_once_per_file(tmp_path: Path) -> None:
    z = np.column_stack([HEART, HEART + 1.0])
    path = _csv(tmp_path / "p.csv", z, header="t,x1,y1,z1,x2,y2,z2")
    with pytest.warns(RecordingWarning, match="pass --units mm") as caught:
        load_recording(path, units="m", point=2)
    assert len(caught) == 1


def test_check_recording_returns_what_it_warned(tmp_path: Path) -> None:
    rec = RecordedMotion(T, HEART)  # metres: 5 m
    with pytest.warns(RecordingWarning):
        messages = check_recording(rec)
    assert len(messages) == 1 and "read in m" in messages[0]
    lenient = Plausibility(max_span=10.0)
    assert check_recording(rec, lenient) == []


def test_a_short_stretch_is_not_judged_on_its_span() -> None:
    rec = RecordedMotion(T[:25], HEART[:25])  # 1 s of complete samples
    assert check_recording(rec) == []


@pytest.mark.parametrize("kwargs", [dict(min_span=0.0), dict(max_span=1e-4),
                                    dict(quantile=0.5), dict(outlier_factor=1.0),
                                    dict(max_missing=1.5), dict(min_seconds=-1.0)])
def test_settings_are_checked(kwargs: dict) -> None:
    with pytest.raises(ValueError):
        Plausibility(**kwargs)


def test_a_mat_file_gets_the_same_check(tmp_path: Path) -> None:
    path = tmp_path / "rec.mat"
    scipy.io.savemat(path, {"X": HEART.T, "fs": 25.0})
    with pytest.warns(RecordingWarning, match="pass --units mm"):
        load_recording(path, units="m")
