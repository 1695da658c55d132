"""Injected faults on tiny streams, against hand-computed samples; their one-line form."""

import math

import numpy as np
import pytest

from rhmpc.sim.sensors import SampleStream
from rhmpc.sim.sensors.faults import (
    EncoderStick,
    FaultSettings,
    NaNBurst,
    SensorFreeze,
    StreamJump,
    parse_fault,
)


def tiny(dim: int = 2) -> SampleStream:
    """Samples at t = 0, 0.1, …, 0.5 s: z_k = (k, 10 k) (and 100 k), arriving 0.05 s late."""
    t = np.arange(6) / 10
    z = np.arange(6)[:, None] * np.array([1.0, 10.0, 100.0])[:dim]
    return SampleStream(t, z, t + 0.05, 10.0)


def rng():
    return np.random.default_rng(0)


def test_freeze_repeats_the_last_sample_before_it_with_stamps_advancing():
    s = tiny()
    out = SensorFreeze(0.2, 0.25).apply(s, rng())  # t = 0.2, 0.3, 0.4 frozen at t = 0.1
    np.testing.assert_array_equal(out.z, [[0, 0], [1, 10], [1, 10], [1, 10], [1, 10], [5, 50]])
    np.testing.assert_array_equal(out.t, s.t)
    np.testing.assert_array_equal(out.arrival, s.arrival)
    np.testing.assert_array_equal(s.z[:, 0], np.arange(6))  # the input is untouched


def test_freeze_from_the_first_sample_holds_it():
    out = SensorFreeze(0.0, 0.15).apply(tiny(), rng())
    np.testing.assert_array_equal(out.z[:3], [[0, 0], [0, 0], [2, 20]])


def test_jump_steps_the_stream_from_its_start_to_its_end():
    out = StreamJump(0.3, offset_m=(5e-3, 0.0, -2e-3)).apply(tiny(3), rng())
    want = tiny(3).z.copy()
    want[3:] += [5e-3, 0.0, -2e-3]
    np.testing.assert_allclose(out.z, want, rtol=0, atol=0)
    back = StreamJump(0.3, offset_m=(1.0, 0, 0), duration_s=0.2).apply(tiny(1), rng())
    np.testing.assert_array_equal(back.z[:, 0], [0, 1, 2, 4, 5, 5])  # t = 0.3, 0.4 only


def test_nan_burst_makes_the_samples_in_its_window_missing():
    out = NaNBurst(0.1, 0.3).apply(tiny(), rng())  # t = 0.1, 0.2, 0.3
    assert np.isnan(out.z[1:4]).all() and np.isfinite(out.z[[0, 4, 5]]).all()
    assert NaNBurst(1.0).duration_s == 0.5


def test_stick_holds_the_chosen_joints_readings():
    readings = tiny(3)  # three joints' angles, one row a tick
    out = EncoderStick(0.25, 0.2, joints=(0, 2)).apply(readings, rng())  # t = 0.3, 0.4
    want = readings.z.copy()
    want[3:5, 0], want[3:5, 2] = 2.0, 200.0  # held at t = 0.2; joint 1 moves on
    np.testing.assert_array_equal(out.z, want)
    every = EncoderStick(0.25, 0.2).apply(readings, rng())
    np.testing.assert_array_equal(every.z[3:5], [[2, 20, 200], [2, 20, 200]])


def test_a_fault_outside_the_stream_changes_nothing():
    s = tiny()
    for fault in (SensorFreeze(5, 1), StreamJump(5), NaNBurst(5), EncoderStick(5, 1)):
        assert fault.apply(s, rng()).z is s.z


@pytest.mark.parametrize(("spec", "fault"), [
    ("freeze@2.0:0.3", SensorFreeze(2.0, 0.3)),
    ("jump@3:5mm", StreamJump(3.0, offset_m=(5e-3, 0.0, 0.0))),
    ("JUMP@3:5,0,-2mm:0.5", StreamJump(3.0, offset_m=(5e-3, 0.0, -2e-3), duration_s=0.5)),
    ("jump@3:500um", StreamJump(3.0, offset_m=(5e-4, 0.0, 0.0))),
    ("nan@4.0", NaNBurst(4.0, 0.5)),
    ("nan@4.0:0.25", NaNBurst(4.0, 0.25)),
    ("stick@5:0.2", EncoderStick(5.0, 0.2)),
    ("stick@5:0.2:0,2", EncoderStick(5.0, 0.2, joints=(0, 2))),
])
def test_one_line_form(spec, fault):
    parsed = parse_fault(spec)
    assert type(parsed) is type(fault)
    assert parsed.start_s == fault.start_s and parsed.duration_s == fault.duration_s
    for name in ("offset_m", "joints"):
        if hasattr(fault, name):
            np.testing.assert_allclose(getattr(parsed, name) or (), getattr(fault, name) or ())
    assert math.isinf(parse_fault("jump@1:1mm").end_s)


@pytest.mark.parametrize(("spec", "message"), [
    ("freeze@2", "expected KIND@START"),
    ("freeze@x:0.3", "the start must be a number"),
    ("freeze@-1:0.3", "start_s must be a finite time >= 0"),
    ("freeze@1:0", "duration_s must be > 0"),
    ("freeze@1:inf", "the duration must be finite"),
    ("nan@nan", "the start must be finite"),
    ("jump@1:5", "needs a length unit"),
    ("jump@1:1,2mm", "one length (along x) or three"),
    ("stick@1:0.2:a", "0-based integers"),
    ("stick@1:0.2:1,1", "distinct integers"),
    ("boom@1:2", "expected KIND@START"),
    ("freeze", "expected KIND@START"),
])
def test_malformed_forms_are_one_line_errors_naming_the_form(spec, message):
    with pytest.raises(ValueError, match="fault") as info:
        parse_fault(spec)
    assert message in str(info.value) and spec in str(info.value)
    assert "\n" not in str(info.value)


def test_settings_check_the_faults_against_the_run():
    settings = FaultSettings(events=["freeze@2:0.3", "jump@3:5mm"])
    assert settings.events == ("freeze@2:0.3", "jump@3:5mm")
    assert [f.kind for f in settings.faults] == ["freeze", "jump"]
    settings.check(10.0)
    with pytest.raises(ValueError, match="starts at 3 s, not within the run's 3 s"):
        settings.check(3.0)
    with pytest.raises(ValueError, match=r"ends at 2\.3 s"):
        settings.check(2.1)
    with pytest.raises(ValueError, match="fault 'nan@x'"):
        FaultSettings(events=("nan@x",))
    with pytest.raises(ValueError, match="events must be a list"):
        FaultSettings(events="nan@1")
    with pytest.raises(ValueError, match="after_s"):
        FaultSettings(after_s=0.0)
