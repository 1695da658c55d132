"""Faults in the loop's inputs: the stream read block by block, the encoders tick by tick, and
the report of what each fault did (the closed loop itself: tests/rhmpc/experiment)."""

import numpy as np
import pytest

from rhmpc.experiment.faults import fault_marks, fault_report
from rhmpc.sim.loop.closed_loop import chunks
from rhmpc.sim.loop.faults import FaultyEncoders, split_faults
from rhmpc.sim.sensors import SampleStream, Upsample
from rhmpc.sim.sensors.faults import EncoderStick, FaultySamples, NaNBurst, SensorFreeze, StreamJump
from rhmpc.sim.sensors.playback import UpsampledSamples
from rhmpc.sim.sensors.stream import ArraySamples, SampledSamples
from tests.sim.loop.stand_ins import HarmonicHeart

FAULTS = (SensorFreeze(0.31, 0.2), StreamJump(0.6, offset_m=(1e-3, 2e-3, 0.0)),
          NaNBurst(0.9, 0.1), SensorFreeze(1.05, 0.1))


def whole(samples) -> tuple:
    return samples.block(0, len(samples))


def faulted(stream: SampleStream) -> np.ndarray:
    rng = np.random.default_rng(0)
    for fault in FAULTS:
        stream = fault.apply(stream, rng)
    return stream.z


def blocks(samples, size: int) -> np.ndarray:
    return np.concatenate([samples.block(a, min(a + size, len(samples)))[1]
                           for a in range(0, len(samples), size)])


def test_faulty_samples_read_in_blocks_are_the_faults_applied_to_the_whole_stream():
    heart = HarmonicHeart()
    source = SampledSamples(heart, 2000.0, 2401)
    t, z, arrival = whole(source)
    want = faulted(SampleStream(t, z, arrival, 2000.0))
    for samples in (source, ArraySamples(t, z, arrival)):
        got = FaultySamples(samples, FAULTS)
        for size in (7, 100, 4096):  # a freeze's held sample lies in an earlier block
            np.testing.assert_array_equal(blocks(got, size), want)
        np.testing.assert_array_equal(got.block(0, len(got))[2], arrival)
    np.testing.assert_array_equal(whole(source)[1], z)  # the source is untouched


def test_a_delivered_stream_and_its_raw_samples_both_carry_the_faults():
    heart = HarmonicHeart()
    t = np.arange(0, 1.3, 1 / 257)
    raw = SampleStream(t, heart.position(t), t.copy(), 257.0)
    delivered = UpsampledSamples(raw, Upsample(2000.0, "linear", True))
    got = FaultySamples(delivered, FAULTS)
    np.testing.assert_array_equal(whole(got.recorded)[1], faulted(raw))
    t2, z2, a2 = whole(delivered)
    np.testing.assert_array_equal(whole(got)[1], faulted(SampleStream(t2, z2, a2, 2000.0)))
    np.testing.assert_array_equal(whole(delivered.recorded)[1], raw.z)  # the truth's samples
    assert not hasattr(FaultySamples(ArraySamples(t, raw.z, t), FAULTS), "recorded")


class Arm:
    """A plant stand-in: q_i = (i, −i, 2i) on tick i."""

    def __init__(self):
        self.i, self.saturated = 0, False

    @property
    def q(self):
        return np.array([1.0, -1.0, 2.0]) * self.i

    def encoders(self):
        return self.q

    def step(self, tau):
        self.i += 1


def test_stuck_encoders_hold_the_reading_before_the_window_while_the_arm_moves():
    Ts = 0.5e-3
    plant = FaultyEncoders(Arm(), [EncoderStick(2 * Ts, 3 * Ts, joints=(0, 2))], Ts)
    readings = []
    for _ in range(7):
        readings.append(plant.encoders())
        plant.step(np.zeros(3))
    want = np.array([1.0, -1.0, 2.0]) * np.arange(7)[:, None]
    want[2:5, 0], want[2:5, 2] = 1.0, 2.0  # ticks 2, 3, 4 hold tick 1's reading
    np.testing.assert_array_equal(readings, want)
    assert plant.held_ticks == 3 and plant.i == 7 and plant.saturated is False  # delegated
    np.testing.assert_array_equal(plant.q, [7.0, -7.0, 14.0])  # the arm is not stuck
    # the same as the fault applied to the stream of readings
    t = np.arange(7) * Ts
    stream = SampleStream(t, np.array([1.0, -1.0, 2.0]) * np.arange(7)[:, None], t, 1 / Ts)
    held = EncoderStick(2 * Ts, 3 * Ts, joints=(0, 2)).apply(stream, np.random.default_rng(0))
    np.testing.assert_array_equal(readings, held.z)


def test_a_stick_of_a_joint_the_arm_lacks_is_refused():
    with pytest.raises(ValueError, match="joint 3 does not exist"):
        FaultyEncoders(Arm(), [EncoderStick(0.0, 1.0, joints=(3,))], 0.5e-3)


def test_chunks_end_at_every_mark():
    assert chunks(10, 4) == [(0, 4), (4, 8), (8, 10)]
    assert chunks(10, 4, [3, 4, 0, 10, 12]) == [(0, 3), (3, 4), (4, 8), (8, 10)]


def segment(i0, i1, error_mm, counts, held=True):
    margin = 0.1 if held else -0.1
    return {"ticks": (i0, i1), "max_error_m": error_mm * 1e-3, "counts": counts,
            "envelope": {"position_margin_rad": margin, "speed_margin_rad_s": 1.0,
                         "held": held}}


def test_the_report_measures_each_window_from_the_segments():
    Ts, faults = 0.5e-3, (NaNBurst(1.0, 0.5), StreamJump(2.0))
    assert split_faults((*faults, EncoderStick(1, 1)))[1] == (EncoderStick(1, 1),)
    assert fault_marks(faults, 1.0, Ts, 3.0) == [2000, 3000, 4000, 5000, 6000]
    segments = [segment(0, 2000, 0.3, {"missing": 1}),
                segment(2000, 3000, 2.0, {"missing": 68, "outliers_rejected": 2}),
                segment(3000, 4000, 1.0, {"missing": 70, "outliers_rejected": 3,
                                          "gate_unlocked": 1}, held=False),
                segment(4000, 5000, 5.0, {"missing": 70, "outliers_rejected": 3,
                                          "gate_unlocked": 2}),
                segment(5000, 6000, 4.0, {"missing": 70, "outliers_rejected": 3,
                                          "gate_unlocked": 2})]
    nan, jump = fault_report(["nan@1", "jump@2:5mm"], faults, segments, 1.0, Ts, 3.0)
    assert nan["during"]["max_error_mm"] == pytest.approx(2.0)
    assert nan["during"]["counts"]["missing"] == 65  # 67 lost, 2 of them rejected by the gate
    assert nan["during"]["counts"]["outliers_rejected"] == 2 and nan["during"]["envelope_held"]
    assert nan["after"]["counts"]["gate_unlocked"] == 2 and not nan["after"]["envelope_held"]
    assert nan["after"]["max_error_mm"] == pytest.approx(5.0)
    assert nan["after"]["position_margin_rad"] == -0.1
    assert jump["end_s"] == 3.0 and jump["after"] is None  # it lasts to the end of the run
    assert jump["during"]["max_error_mm"] == pytest.approx(5.0)
    assert jump["during"]["counts"]["gate_unlocked"] == 1
