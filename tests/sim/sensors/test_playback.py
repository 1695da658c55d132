"""Delivery to the 2-kHz loop: the causal playbacks never deliver a sample before it arrived."""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.sim.heart import make_scenario
from rhmpc.sim.loop.streams import StreamCursor
from rhmpc.sim.sensors import PLAYBACKS, Sensor, playback, sensor_from_name
from rhmpc.sim.sensors.playback import UpsampledSamples
from rhmpc.sim.sensors.stream import Latency

TS = 5e-4


@pytest.fixture(scope="module")
def raw():
    src = make_scenario("fixed-a2-top", duration=12.0).source
    return Sensor(257.0, (Latency(0.004),)).measure(src, 10.0, np.random.default_rng(0))


def _inputs(raw, t, method: str) -> tuple[np.ndarray, np.ndarray]:
    """Indices (older, newer) of the raw samples a delivered sample at ``t`` is made of."""
    k = np.clip(np.searchsorted(raw.t, t + 1e-12, side="right") - 1, 0, len(raw) - 1)
    if method == "hold":
        return k, k
    newer = np.where(np.isclose(raw.t[k], t, atol=1e-12), k, np.minimum(k + 1, len(raw) - 1))
    return k, newer


@pytest.mark.parametrize("name", ["hold", "linear"])
def test_causal_playback_reads_nothing_before_its_arrival(raw, name: str) -> None:
    """Tolerance 0: every raw sample a delivered value uses has arrived by the delivery."""
    up = playback(name, 2000.0).apply(raw, None)
    method = PLAYBACKS[name][0]
    _, newer = _inputs(raw, up.t, method)
    assert np.all(raw.arrival[newer] <= up.arrival + 1e-12)
    # and the loop's cursor, at every tick, holds only samples that have arrived
    cursor = StreamCursor(UpsampledSamples(raw, playback(name, 2000.0)))
    for i in range(0, 18000, 7):
        now = i * TS
        j = cursor.newest(now + 1e-12)
        if j >= 0:
            t_j, _ = cursor.sample(j)
            _, k = _inputs(raw, np.array([t_j]), method)
            assert raw.arrival[k[0]] <= now + 1e-12


def test_linear_playback_is_one_raw_period_old_and_offline_is_not_causal(raw) -> None:
    """Linear: age = 1/257 s + latency at every delivery (1e-12 s). Offline reads the future:
    some delivered value depends on a raw sample that arrives up to one raw period later."""
    lin = playback("linear", 2000.0).apply(raw, None)
    np.testing.assert_allclose(lin.arrival[:-600] - lin.t[:-600], 1 / 257 + 0.004, atol=1e-12)
    off = playback("offline", 2000.0).apply(raw, None)
    _, newer = _inputs(raw, off.t, "linear")
    early = raw.arrival[newer] - off.arrival
    assert early.max() == pytest.approx(1 / 257, abs=TS)


def test_hold_keeps_the_measurement_time(raw) -> None:
    up = playback("hold", 2000.0).apply(raw, None)
    k = np.searchsorted(raw.t, up.t, side="left")
    np.testing.assert_array_equal(raw.t[k], up.t)
    np.testing.assert_array_equal(raw.z[k], up.z)


def test_default_playback_is_causal() -> None:
    s = sensor_from_name("white", upsample=2000.0)
    assert s.stages[-1] == playback("linear", 2000.0) and s.stages[-1].causal
    with pytest.raises(ValueError, match="hold, linear, offline"):
        sensor_from_name("white", upsample=2000.0, playback="later")
