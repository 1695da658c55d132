"""Units by evidence: times read in seconds are checked against a plausible heartbeat and
sampling rate, whatever the rate (hypothesis over rates, heart rates and units)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rhmpc.sim.recordings import RecordingError, load_recording
from rhmpc.sim.recordings.recorded import RecordedMotion
from rhmpc.sim.recordings.timebase import check_time_unit, strongest_frequency


def motion(t_seconds: np.ndarray, bpm: float, breaths: float = 15.0) -> np.ndarray:
    """Heart-like motion [mm]: a beat of 3 mm and breathing of 1 mm."""
    f, b = bpm / 60.0, breaths / 60.0
    return np.column_stack([3 * np.sin(2 * np.pi * f * t_seconds),
                            2 * np.cos(2 * np.pi * f * t_seconds),
                            np.sin(2 * np.pi * b * t_seconds)])


def write_csv(path: Path, t: np.ndarray, z: np.ndarray, t_name: str = "t") -> Path:
    np.savetxt(path, np.c_[t, z], delimiter=",", header=f"{t_name},x,y,z", comments="",
               fmt="%.6f")
    return path


def test_a_1_khz_file_in_milliseconds_is_refused_with_the_unit_to_state(tmp_path) -> None:
    t = np.arange(6000.0)  # ms
    path = write_csv(tmp_path / "ms1k.csv", t, motion(t / 1000, 72))
    with pytest.raises(RecordingError, match=r"ms1k\.csv: the times look like milliseconds: "
                       r"read in seconds it is sampled at 1 Hz .* read in ms it is sampled at "
                       r"1000 Hz and beats at 7\d/min: state the unit \(a CSV header t_ms\)"):
        load_recording(path)
    rec = load_recording(write_csv(tmp_path / "stated.csv", t, motion(t / 1000, 72), "t_ms"))
    assert rec.sample_rate == pytest.approx(1000.0)


def test_frame_numbers_are_refused_with_the_frame_rates_a_heartbeat_needs(tmp_path) -> None:
    frames = np.arange(750.0)  # 30 s at 25 frames/s
    path = write_csv(tmp_path / "frames.csv", frames, motion(frames / 25, 72))
    with pytest.raises(RecordingError, match=r"frames\.csv: the times look like frame numbers "
                       r"\(steps of 1\).*the frames came at \d+–\d+ per second: write the "
                       r"times in seconds"):
        load_recording(path)


def test_a_recording_without_a_rhythm_keeps_its_reading() -> None:
    t = np.arange(100.0)
    flat = RecordedMotion(t, np.zeros((100, 3)), "flat.csv")
    assert strongest_frequency(flat) is None
    check_time_unit(flat)  # no evidence: read in seconds, as the format says


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@pytest.mark.slow
@given(rate=st.sampled_from([25.0, 30.0, 100.0, 257.0, 1000.0, 2000.0]),
       bpm=st.floats(40.0, 180.0), seconds=st.floats(8.0, 30.0),
       unit=st.sampled_from(["s", "ms"]), stated=st.booleans())
def test_seconds_pass_and_unstated_milliseconds_do_not(tmp_path, rate: float, bpm: float,
                                                       seconds: float, unit: str,
                                                       stated: bool) -> None:
    t = np.arange(round(seconds * rate)) / rate
    factor = 1000.0 if unit == "ms" else 1.0
    name = f"t_{unit}" if stated else "t"
    path = write_csv(tmp_path / "rec.csv", t * factor, motion(t, bpm), name)
    if unit == "ms" and not stated:
        with pytest.raises(RecordingError, match=r"millisecond|one sample every"):
            load_recording(path)
    else:
        assert load_recording(path).sample_rate == pytest.approx(rate, rel=1e-3)
