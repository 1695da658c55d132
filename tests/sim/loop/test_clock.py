"""The predictor's clock: a slow sensor's raw samples go to the predictor once each, on arrival."""

from __future__ import annotations

import numpy as np
import pytest

from sim.loop import LoopSettings
from sim.loop.clock import arrival_tick, predictor_clock
from sim.loop.closed_loop import OpenLoop
from sim.loop.streams import ArraySamples, UpsampledSamples
from sim.sensors import SampleStream, playback
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


class Spy:
    """A reference that records what the open loop feeds it."""

    def __init__(self) -> None:
        self.updates: list[tuple[int, np.ndarray | None, float]] = []
        self.forecasts = 0

    def update(self, tick, z, stamp):
        self.updates.append((tick, None if z is None else np.array(z), stamp))

    def learn(self):
        pass

    def predict(self):
        self.forecasts += 1

    def interpolate(self):
        pass

    def horizons(self, tick, count):
        return None


@pytest.mark.parametrize("pipelined", [True, False])
def test_each_raw_sample_reaches_the_predictor_once_with_its_own_time_stamp(pipelined):
    """The anchor of every update is the raw sample's measurement time (no interpolation lag),
    fed on the tick it arrives (a 12-ms latency, jittered time stamps)."""
    raw = _raw(28.0, 3.0, latency=0.012, jitter=2e-3, rng=np.random.default_rng(3))
    settings = LoopSettings(duration=3.0, settling=1.0, pipelined_refresh=pipelined)
    clock = predictor_clock(settings, raw)
    spy = Spy()
    open_loop = OpenLoop(spy, raw, np.zeros(3), settings, np.zeros((50, 3)), clock)
    for c0 in range(0, settings.ticks, 1000):  # chunks that cut through refresh periods
        refs, charged, _ = open_loop.chunk(c0, min(c0 + 1000, settings.ticks))
        # the update, the learning, the forecast, the interpolation, the error bookkeeping
        assert len(charged) == 5
        assert len(refs) == len(charged[0]) == min(1000, settings.ticks - c0)
    fed = [u for u in spy.updates if u[1] is not None]
    lag = 3 if pipelined else 0  # update, learning, forecast, interpolation on 4 ticks
    arrived = raw.arrival <= (settings.ticks - 1 - lag) * TS
    np.testing.assert_array_equal([u[2] for u in fed], raw.t[arrived])
    np.testing.assert_array_equal([u[1] for u in fed], raw.z[arrived])
    assert [u[0] for u in fed] == [arrival_tick(a, TS) for a in raw.arrival[arrived]]
    assert spy.forecasts == len(fed)


def test_a_gap_in_the_time_stamps_is_fed_as_missing_samples():
    raw = _raw(25.0, 2.0)
    keep = np.ones(raw.t.size, bool)
    keep[[10, 11, 12, 30]] = False  # three and one samples lost, without NaN rows
    raw = ArraySamples(raw.t[keep], raw.z[keep], raw.arrival[keep])
    settings = LoopSettings(duration=2.0, settling=0.5)
    spy = Spy()
    open_loop = OpenLoop(spy, raw, np.zeros(3), settings, None, predictor_clock(settings, raw))
    open_loop.chunk(0, settings.ticks)
    missing = [k for k, u in enumerate(spy.updates) if u[1] is None]
    assert missing == [10, 11, 12, 30]
    assert len(spy.updates) == 50  # one slot per 40 ms up to the last sample, 1.96 s


class Stamped:
    """A reference that notes how many control ticks had run when each slice of it ran."""

    def __init__(self, done: list[int]) -> None:
        self.done, self.calls, self.updates = done, [], []

    def _note(self, name: str) -> None:
        self.calls.append((name, self.done[0]))

    def update(self, tick, z, stamp):
        self._note("update")
        self.updates.append((tick, z))

    def learn(self):
        self._note("learn")

    def predict(self):
        self._note("predict")

    def interpolate(self):
        self._note("interpolate")

    def score(self):
        self._note("score")

    def horizons(self, tick, count):
        return None


def _drive(rate: float, pipelined: bool, latency: float = 0.0, duration: float = 0.3):
    """Run an open loop over a stamped spy, one control tick per reference."""
    settings = LoopSettings(duration=duration, settling=0.0, pipelined_refresh=pipelined)
    raw = _raw(rate, 0.5, latency=latency)
    done = [0]  # control ticks run so far
    spy = Stamped(done)
    open_loop = OpenLoop(spy, raw, np.zeros(3), settings, np.zeros((50, 3)),
                         predictor_clock(settings, raw))
    n = settings.ticks
    charged = tuple([0] * n for _ in range(5))
    for _ in open_loop.references(0, n, charged, []):
        done[0] += 1  # the control tick that uses the reference
    return spy, open_loop, charged, n


NAMES = ["update", "learn", "predict", "interpolate", "score"]


@pytest.mark.parametrize("pipelined", [True, False])
def test_each_slice_runs_on_its_own_tick_between_the_control_ticks(pipelined):
    """A refresh on tick r: update, learning, forecast on ticks r − 3, r − 2, r − 1, the
    interpolation on r, the bookkeeping on r + 1 when pipelined; all on r otherwise. Each runs
    after the control ticks before its own, before its own tick's, and is charged to it."""
    spy, _, charged, n = _drive(257.0, pipelined)  # the downsample clock: every 15 ticks
    offsets = [-3, -2, -1, 0, 1] if pipelined else [0, 0, 0, 0, 0]
    for r in range(15, n - 15, 15):
        for part, (name, offset) in enumerate(zip(NAMES, offsets, strict=True)):
            assert (name, r + offset) in spy.calls, (name, r, offset)
            assert charged[part][r + offset] > 0
    # the first refresh, on tick 0: what falls before the run runs on tick 0, as it always did
    first = [name for name, done in spy.calls if done == 0]
    assert first == NAMES[:4] + ([] if pipelined else ["score"])
    assert spy.updates[0] == ((-3, None) if pipelined else (0, spy.updates[0][1]))


def test_on_the_sensor_clock_each_refresh_follows_its_sample_by_the_pipeline():
    """25 Hz, 12 ms latency: the update on the tick the sample arrives, the interpolation
    three ticks later, every refresh's slices in order."""
    spy, _, _, _ = _drive(25.0, True, latency=0.012)
    updates = [done for name, done in spy.calls if name == "update"]
    refreshes = [done for name, done in spy.calls if name == "interpolate"]
    assert len(updates) == len(refreshes) >= 7
    assert [r - u for u, r in zip(updates, refreshes, strict=True)] == [3] * len(updates)
    assert updates[0] == arrival_tick(0.012, TS)
    order = [name for name, _ in spy.calls if name != "score"]
    assert order == NAMES[:4] * len(updates)


@pytest.mark.parametrize("pipelined", [True, False])
def test_after_the_run_finish_makes_what_a_pipelined_refresh_made_ahead(pipelined):
    # 601 ticks: the last refresh is on the last tick, 600
    spy, open_loop, _, n = _drive(257.0, pipelined, duration=0.3005)
    assert n == 601 and ("interpolate", 600) in spy.calls
    before = len(spy.calls)
    open_loop.finish()
    after = [name for name, _ in spy.calls[before:]]
    if pipelined:  # the last refresh's bookkeeping and the next update, learning, forecast
        assert after == ["score", "update", "learn", "predict"]
    else:
        assert after == []
    assert not open_loop.slices


@pytest.mark.parametrize(("rate", "pipelined"), [(257.0, True), (257.0, False), (25.0, True)])
def test_segments_cover_the_ticks_with_the_slices_on_their_first_ticks(rate, pipelined):
    """The ticks of a segment run back to back: every tick once, in order, and every slice
    before the first tick of a segment (the compiled ticks run a segment in one call)."""
    settings = LoopSettings(duration=0.3, settling=0.0, pipelined_refresh=pipelined)
    raw = _raw(rate, 0.5, latency=0.012 if rate < 100 else 0.0)
    done = [0]
    spy = Stamped(done)
    open_loop = OpenLoop(spy, raw, np.zeros(3), settings, np.zeros((50, 3)),
                         predictor_clock(settings, raw))
    n = settings.ticks
    charged = tuple([0] * n for _ in range(5))
    starts = []
    for i, refs, address in open_loop.segments(0, n, charged, []):
        assert i == done[0] and 1 <= len(refs) <= OpenLoop.PERIOD
        assert address == refs.__array_interface__["data"][0]
        starts.append(i)
        done[0] += len(refs)  # the segment's control ticks
    assert done[0] == n
    sliced = {tick for part in charged for tick, ns in enumerate(part) if ns > 0}
    assert sliced <= set(starts)
    assert {t for _, t in spy.calls} <= set(starts) | {n}


@pytest.mark.parametrize("downsample", [15, 700])
def test_segments_hold_each_ticks_own_points(downsample):
    """Each tick of a segment gets its own r_{i+1..i+N}, also when a period is longer than the
    points fetched at once (``OpenLoop.PERIOD``): the exact reference over known points."""
    from rhmpc.control.reference import ExactReference

    settings = LoopSettings(duration=1.0, settling=0.0, downsample=downsample)
    n, N = settings.ticks, settings.horizon
    truth = np.arange(3.0 * (n + N + 1)).reshape(-1, 3)
    exact = ExactReference(truth, N)
    exact.place(np.zeros(3))
    open_loop = OpenLoop(exact, ideal_stream(HarmonicHeart(), 1.1), np.zeros(3), settings,
                         np.zeros((N, 3)))
    charged = tuple([0] * n for _ in range(5))
    ticks = 0
    for i, refs, address in open_loop.segments(0, n, charged, []):
        assert address == refs.__array_interface__["data"][0]
        for k, ref in enumerate(refs):
            np.testing.assert_array_equal(ref, truth[i + k + 1 : i + k + 1 + N])
        ticks += len(refs)
    assert ticks == n
