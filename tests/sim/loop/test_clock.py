"""The predictor's clock: a slow sensor's raw samples go to the predictor once each, on arrival."""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.sim.loop import LoopSettings
from rhmpc.sim.loop.clock import arrival_tick, predictor_clock
from rhmpc.sim.loop.closed_loop import Refreshes
from rhmpc.sim.sensors import SampleStream, playback
from rhmpc.sim.sensors.playback import UpsampledSamples
from rhmpc.sim.sensors.stream import ArraySamples
from tests.sim.loop.stand_ins import HarmonicHeart, ideal_stream

TS = 0.5e-3


def _raw(rate: float, seconds: float, latency: float = 0.0, jitter: float = 0.0,
         rng: np.random.Generator | None = None) -> ArraySamples:
    t = np.arange(0.0, seconds, 1.0 / rate)
    if jitter:
        t = t + rng.uniform(-jitter, jitter, t.size)
    z = HarmonicHeart().position(t)
    return ArraySamples(t, z, t + latency)


@pytest.mark.parametrize(("rate", "mode"), [(25.0, "sensor"), (30.0, "sensor"), (100.0, "sensor"),
                                            (257.0, "downsample"), (404.0, "downsample")])
def test_auto_picks_the_sensor_clock_for_sensors_slower_than_the_predictor(rate, mode):
    raw = _raw(rate, 2.0)
    upsampled = UpsampledSamples(SampleStream(raw.t, raw.z, raw.arrival, rate),
                                 playback("linear", 1 / TS))
    clock = predictor_clock(LoopSettings(), upsampled)
    assert clock.mode == mode
    assert clock.sensor_rate == pytest.approx(rate)
    if mode == "sensor":
        assert clock.dt == pytest.approx(1 / rate)
        assert clock.refresh_ticks == int(np.ceil(1.5 / rate / TS - 1e-9))
        assert clock.raw.t is not None and len(clock.raw) == raw.t.size  # the raw samples
    else:
        assert clock.dt == pytest.approx(15 * TS) and clock.refresh_ticks == 15


def test_the_clock_can_be_forced_either_way():
    raw = _raw(25.0, 2.0)
    assert predictor_clock(LoopSettings(predictor_clock="downsample"), raw).mode == "downsample"
    fast = ideal_stream(HarmonicHeart(), 1.0)
    assert predictor_clock(LoopSettings(predictor_clock="sensor"), fast).dt == pytest.approx(TS)
    with pytest.raises(ValueError, match="predictor_clock"):
        LoopSettings(predictor_clock="sometimes")


def _due(settings: LoopSettings, raw, ticks: int | None = None) -> list[tuple[int, object, float]]:
    """Every refresh the loop would make: (tick, z or None, stamp)."""
    refreshes = Refreshes(raw, settings, predictor_clock(settings, raw))
    return [(i, z, stamp) for i in range(settings.ticks if ticks is None else ticks)
            for z, stamp, _ in refreshes.due(i)]


def test_each_raw_sample_reaches_the_predictor_once_with_its_own_time_stamp():
    """The anchor of every refresh is the raw sample's measurement time (no interpolation lag),
    fed on the tick it arrives (a 12-ms latency, jittered time stamps)."""
    raw = _raw(28.0, 3.0, latency=0.012, jitter=2e-3, rng=np.random.default_rng(3))
    settings = LoopSettings(duration=3.0, settling=1.0)
    fed = [u for u in _due(settings, raw) if u[1] is not None]
    arrived = raw.arrival <= (settings.ticks - 1) * TS
    np.testing.assert_array_equal([u[2] for u in fed], raw.t[arrived])
    np.testing.assert_array_equal([u[1] for u in fed], raw.z[arrived])
    assert [u[0] for u in fed] == [arrival_tick(a, TS) for a in raw.arrival[arrived]]


def test_a_gap_in_the_time_stamps_is_fed_as_missing_samples():
    raw = _raw(25.0, 2.0)
    keep = np.ones(raw.t.size, bool)
    keep[[10, 11, 12, 30]] = False  # three and one samples lost, without NaN rows
    raw = ArraySamples(raw.t[keep], raw.z[keep], raw.arrival[keep])
    due = _due(LoopSettings(duration=2.0, settling=0.5), raw)
    missing = [k for k, u in enumerate(due) if u[1] is None]
    assert missing == [10, 11, 12, 30]
    assert len(due) == 50  # one slot per 40 ms up to the last sample, 1.96 s


def test_the_downsample_clock_refreshes_every_downsample_ticks_with_the_newest_sample():
    """Tuna et al.'s protocol: every 15 ticks the newest sample delivered to the control rate
    (the tick's time and None when none is new since the last refresh)."""
    stream = ideal_stream(HarmonicHeart(), 1.0, rate=257.0, latency=1.5e-3)
    settings = LoopSettings(duration=1.0, settling=0.0)
    due = _due(settings, stream)
    assert [u[0] for u in due] == list(range(0, settings.ticks, 15))
    for tick, z, stamp in due:
        arrived = np.flatnonzero(stream.arrival <= tick * TS + 1e-12)
        if z is None:
            assert stamp == tick * TS
            continue
        j = arrived[-1]
        assert stamp == stream.t[j]
        np.testing.assert_array_equal(z, stream.z[j])


def test_the_loop_refreshes_the_controller_with_every_due_sample():
    """run_closed_loop feeds its controller exactly the refreshes of the schedule, each on its
    tick and before that tick's step."""
    from tests.sim.loop.test_loop import spy_run

    stream = ideal_stream(HarmonicHeart(), 0.5, rate=28.0, latency=4e-3)
    settings = LoopSettings(duration=0.4, settling=0.0)
    calls = spy_run(stream, settings)
    expected = [(i, stamp) for i, _, stamp in _due(settings, stream)]
    assert [(i, stamp) for kind, i, stamp in calls if kind == "refresh"] == expected
    steps = [i for kind, i, _ in calls if kind == "step"]
    assert steps == list(range(settings.ticks))
    order = [(i, kind) for kind, i, _ in calls]
    assert order == sorted(order, key=lambda e: (e[0], e[1] == "step"))
