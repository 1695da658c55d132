"""Gap repair of the tapped delay line: the RLS predictors after a rejected sample.

On the nearly noise-free stream of the physical sonomicrometer the RLS weights are large and
cancel each other (a smooth signal extrapolated 25 ms), so a step between the open-loop fills
of a gap and the next measurement is amplified into misses of several millimetres unless the
gap is repaired (without repair, an echo outlier rejected by the loop's gate makes the
generalized predictor miss by 9 mm at 25 ms).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from rhmpc.predictors import make_predictor
from rhmpc.predictors.delay_line import TappedDelayLine


def test_fills_are_corrected_by_the_bridge_ramp():
    line = TappedDelayLine(6, 2)
    for k in range(3):
        line.push(np.array([k, -k], dtype=float))
    fills = [np.array([10.0, 1.0]), np.array([20.0, 2.0]), np.array([30.0, 3.0])]
    for f in fills:
        line.push(f, measured=False)
    assert line.fills == 3 and line.real_run == 0
    z, expected = np.array([44.0, 4.0]), np.array([40.0, 6.0])
    line.push(z, expected=expected)
    miss = z - expected
    # newest first: z, then fill 3, 2, 1 corrected by 3/4, 2/4, 1/4 of the miss, then data
    want = [z, fills[2] + 0.75 * miss, fills[1] + 0.5 * miss, fills[0] + 0.25 * miss,
            [2.0, -2.0], [1.0, -1.0]]
    np.testing.assert_allclose(line.buf, want, rtol=0, atol=1e-12)
    assert line.fills == 0 and line.real_run == 1


@pytest.mark.parametrize("gap", [1, 2, 3])
def test_second_measurement_after_a_gap_interpolates_it_by_the_cubic(gap):
    """A cubic signal is reproduced exactly in the gap once two samples on each side are known;
    a gap longer than ``INTERPOLATE_GAP`` keeps its (ramp-repaired) fills."""
    cubic = lambda k: np.array([0.3 * k**3 - 2.0 * k**2 + k - 5.0, -0.1 * k**3 + 4.0])  # noqa: E731
    line = TappedDelayLine(10, 2)
    for k in range(4):
        line.push(cubic(k))
    for _ in range(gap):
        line.push(np.array([99.0, -99.0]), measured=False)  # a wild fill
    line.push(cubic(4 + gap), expected=np.zeros(2))
    line.push(cubic(5 + gap))
    want = np.array([cubic(k) for k in range(5 + gap, -1, -1)])
    np.testing.assert_allclose(line.buf[: 6 + gap], want, rtol=0, atol=1e-9)
    assert line.measured[: 6 + gap].tolist() == [True, True] + [False] * gap + [True] * 4
    longer = TappedDelayLine(12, 1)
    for k in range(3):
        longer.push(np.array([float(k)]))
    for _ in range(TappedDelayLine.INTERPOLATE_GAP + 1):
        longer.push(np.array([50.0]), measured=False)
    longer.push(np.array([7.0]))
    longer.push(np.array([8.0]))
    assert (longer.buf[2 : 3 + TappedDelayLine.INTERPOLATE_GAP] > 7.0).all()


def test_no_repair_without_a_forecast_or_a_finite_one():
    line = TappedDelayLine(4, 1)
    line.push(np.array([1.0]))
    line.push(np.array([5.0]), measured=False)
    before = line.buf.copy()
    line.push(np.array([2.0]), expected=np.array([np.nan]))
    np.testing.assert_array_equal(line.buf[1:], before[:-1])


def _stream(seconds: float = 25.0) -> np.ndarray:
    """The physical sonomicrometer at 133 Hz on the varying-a1-top replica (no echo outliers,
    no white range error: the repair is measured against the smooth part of the forecast miss)."""
    sim_heart = pytest.importorskip("rhmpc.sim.heart")
    sim_sensors = pytest.importorskip("rhmpc.sim.sensors")
    scn = sim_heart.make_scenario("varying-a1-top", np.random.default_rng(2), duration=seconds)
    sensor = sim_sensors.sensor_from_name("sonomicrometry", dim=3, outliers=False,
                                          upsample=1 / 0.0075, range_noise=0.0)
    return sensor.measure(scn.source, seconds, np.random.default_rng(2)).z


def _worst_after_gaps(name: str, z: np.ndarray, gap: int) -> tuple[float, float]:
    """(worst, baseline): the largest 30-ms forecast error in the 25 samples after a gap of
    ``gap`` samples, at 25 instants from 15 s on, and the largest without the gap."""
    p = make_predictor(name, 0.0075)
    worst = baseline = 0.0
    n = 0
    for n0 in range(2000, 2000 + 25 * 40, 40):
        while n < n0:
            p.update(z[n])
            n += 1
        for with_gap in (True, False):
            q = copy.deepcopy(p)
            for k in range(n0, n0 + gap + 25):
                q.update(None if with_gap and k < n0 + gap else z[k])
                if k >= n0 + gap:
                    e = float(np.linalg.norm(q.predict(4)[3] - z[k + 4]))
                    if with_gap:
                        worst = max(worst, e)
                    else:
                        baseline = max(baseline, e)
    return worst, baseline


@pytest.mark.parametrize("name", ["generalized", "one-step"])
@pytest.mark.slow
def test_rls_predictors_recover_from_a_two_sample_gap(name, monkeypatch):
    z = _stream()
    worst, baseline = _worst_after_gaps(name, z, gap=2)
    # measured: 2.28 / 0.98 mm (generalized), 1.30 / 0.87 mm (one-step)
    assert worst <= 3.0 * baseline
    # the same gaps without the repair: 5.55 and 3.55 mm (the defect this guards against)
    push = TappedDelayLine.push
    monkeypatch.setattr(TappedDelayLine, "push",
                        lambda self, z, measured=True, expected=None: push(self, z, measured))
    unrepaired, _ = _worst_after_gaps(name, z, gap=2)
    assert unrepaired >= 4.0 * baseline


@pytest.mark.slow
def test_retract_replaces_the_newest_sample_by_its_forecast():
    z = _stream(12.0)
    for name in ("generalized", "one-step"):
        p = make_predictor(name, 0.0075)
        for k in range(1500):
            p.update(z[k])
        before = p.predict(1)[0]  # the forecast of sample 1500 from the samples up to 1499
        p.update(z[1500] + 1e-3)
        assert p.retract() and p.counts["retracted"] == 1
        # the weights keep the one update the outlier made, so the replacement is the forecast up
        # to that: measured 0.2 µm (generalized) and 40 µm (one-step, which learns the outlier as
        # a target at once) for this 1 mm outlier
        np.testing.assert_allclose(p.line.buf[0], before, rtol=0, atol=1e-4)
        assert not p.retract()  # its replacement is not a measurement: nothing more to retract
    for name in ("hold", "ekf", "wflc"):  # the default: cannot, and nothing changes
        p = make_predictor(name, 0.0075)
        for k in range(1500):
            p.update(z[k])
        assert not p.retract() and "retracted" not in p.counts


@pytest.mark.parametrize("name", ["one-step", "generalized"])
def test_each_repaired_gap_is_counted_once(name):
    """``counts["repaired"]``: one a gap whose fills the returning measurement corrected; none
    for gaps before the predictor is ready (its fills are holds, nothing to correct)."""
    t = np.arange(0.0, 6.0, 1 / 133)
    z = np.c_[np.sin(2 * np.pi * 1.2 * t), np.cos(2 * np.pi * 0.3 * t)] * 1e-3
    predictor = make_predictor(name, 1 / 133, unit=1.0)
    gaps = {3: 2, 400: 1, 500: 3, 600: 7}  # start: length; the first before it is ready
    k = 0
    while k < len(t):
        if k in gaps:
            for _ in range(gaps[k]):
                predictor.update(None)
            k += gaps[k]
        predictor.update(z[k])
        k += 1
    assert predictor.counts["missing"] == sum(gaps.values())
    assert predictor.counts["repaired"] == 3
