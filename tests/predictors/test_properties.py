"""The contract every predictor keeps on any finite bounded input (hypothesis property tests).

For any input 1-D or 3-D, in m or mm, sampled at 25 Hz to 2 kHz, with NaN gaps:
every update/predict returns (small sizes keep the run bounded; a hang fails the
deadline), forecasts are finite and inside the divergence guard's band
[lo − G·r, hi + G·r] of the recent range, and the state recovers after a gap.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rhmpc.predictors import PREDICTORS, make_predictor
from rhmpc.predictors.base import Predictor
from rhmpc.predictors.monitor import infer_unit
from tests.predictors.helpers import HarmonicSource, each

NAMES = each(n for n in PREDICTORS if n != "exact")
RATES = (25.0, 28.0, 133.3, 500.0, 2000.0)


@st.composite
def signals(draw):
    """(dt, z): a few seconds of heart-like, chirp, constant or noise input, with NaN gaps."""
    rate = draw(st.sampled_from(RATES))
    d = draw(st.sampled_from([1, 3]))
    scale = draw(st.sampled_from([1.0, 1e-3]))  # mm or m
    T = draw(st.integers(20, 160)) if rate < 100 else draw(st.integers(50, 400))
    kind = draw(st.sampled_from(["heart", "chirp", "constant", "noise", "steps"]))
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    t = np.arange(T) / rate
    f = draw(st.floats(0.3, 4.0))
    amp = draw(st.floats(0.01, 30.0)) * scale
    if kind == "heart":
        z = amp * np.sin(2 * np.pi * f * t)[:, None] + 0.3 * amp * np.sin(
            2 * np.pi * 0.2 * t[:, None] + rng.uniform(0, 6, d)
        )
    elif kind == "chirp":
        z = amp * np.sin(2 * np.pi * (f * t + 2 * t**2))[:, None] * np.ones(d)
    elif kind == "constant":
        z = np.full((T, d), amp)
    elif kind == "steps":
        z = amp * np.repeat(rng.integers(-3, 4, (T // 10 + 1, d)), 10, axis=0)[:T]
    else:
        z = amp * rng.standard_normal((T, d))
    z = z + draw(st.floats(-500.0, 500.0)) * scale
    gaps = draw(st.lists(st.tuples(st.integers(0, T - 1), st.integers(1, T)), max_size=3))
    for a, n in gaps:
        z[a : a + n] = np.nan
    return 1.0 / rate, z


def _check(p: Predictor, z: np.ndarray, steps: int = 5) -> None:
    g = p.GUARD_MULTIPLE
    for k, zk in enumerate(z):
        p.update(zk)
        if p._last is None:
            continue
        f = p.predict(steps)
        assert f.shape == (steps, z.shape[1])
        assert np.isfinite(f).all()
        lo, hi = p._envelope.envelope()
        r = np.maximum(hi - lo, 0.1 * (hi - lo).max())
        assert np.all(f >= lo - g * r - 1e-9 * (1 + abs(lo))), (k, f, lo, r)
        assert np.all(f <= hi + g * r + 1e-9 * (1 + abs(hi))), (k, f, hi, r)


@pytest.mark.parametrize("name", NAMES)
@settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow], derandomize=True
)
@given(case=signals())
def test_any_bounded_input_gives_finite_guarded_forecasts(name, case):
    dt, z = case
    # short initialisation windows so that the model-based predictors run within the example
    kw = {"init_seconds": 20 * dt} if name in ("ekf", "wflc") else {}
    _check(make_predictor(name, dt, **kw), z)


@pytest.mark.parametrize("name", NAMES)
def test_guard_clips_and_counts_a_diverging_forecast(name):
    dt = 1 / 50
    z = HarmonicSource().position(np.arange(600) * dt)
    p = make_predictor(name, dt)
    for zk in z:
        p.update(zk)
    p._predict = lambda steps: np.full((steps, 3), 1e9)  # a diverged model
    f = p.predict(4)
    lo, hi = p._envelope.envelope()
    assert p.counts["forecast_clamped"] == 1
    assert np.all(f <= hi + p.GUARD_MULTIPLE * (hi - lo).max() + 1e-12)
    p._predict = lambda steps: np.full((steps, 3), np.nan)
    np.testing.assert_array_equal(p.predict(2), [z[-1], z[-1]])
    assert p.counts["forecast_nonfinite"] == 1
    for zk in z:  # and it learns again
        p.update(zk)
    p._predict = lambda steps: np.full((steps, 3), 1e160)  # finite, its square is not
    f = p.predict(1)
    np.testing.assert_array_equal(f, [p._bounds[1]])
    assert p.counts["forecast_clamped"] == 2 and p.counts["forecast_nonfinite"] == 1
    for count, bad in enumerate((np.inf, -np.inf), start=2):  # not clipped to a finite one
        p._predict = lambda steps, v=bad: np.full((steps, 3), v)
        np.testing.assert_array_equal(p.predict(1), [z[-1]])
        assert p.counts["forecast_nonfinite"] == count
        for zk in z:
            p.update(zk)
    assert np.isfinite(type(p)._predict(p, 3)).all()


#: Relative tolerance of the m-vs-mm comparison. The AR fits solve normal equations of a smooth
#: signal's autocorrelation, which are ill-conditioned, so the rounding of the ×1000 scale
#: comes back amplified: measured up to 1.3e-6 for ``ar``/``fading-ar`` (on this machine's
#: BLAS), ≤ 2e-9 for the others (1e-6 kept). Margin ×7.7 on the measured value.
SCALE_RTOL = {"ar": 1e-5, "fading-ar": 1e-5}


@pytest.mark.parametrize("name", NAMES)
def test_same_forecasts_in_metres_and_millimetres_without_unit(name):
    dt = 1 / 100
    t = np.arange(int(14 / dt)) * dt
    src = HarmonicSource(f_hz=1.3, breathing=(0.25, [2e-3, 1e-3, 0.5e-3]))
    z = src.position(t) + 50e-6 * np.random.default_rng(3).standard_normal((t.size, 3))
    z[500:520] = np.nan
    p_m, p_mm = make_predictor(name, dt), make_predictor(name, dt)
    for k in range(t.size):
        p_m.update(z[k])
        p_mm.update(1e3 * z[k])
        if k % 37 == 0:
            np.testing.assert_allclose(
                p_mm.predict(6), 1e3 * p_m.predict(6), rtol=SCALE_RTOL.get(name, 1e-6),
                atol=1e-9 * 1e3,
            )
    if hasattr(p_m.settings, "unit"):
        assert (p_m.unit, p_mm.unit) == (1.0, 1e-3)


def test_infer_unit_snaps_to_powers_of_1000():
    z = HarmonicSource().position(np.arange(100) * 0.01)  # ≈ 10 mm range, in m
    assert infer_unit(z) == 1.0
    assert infer_unit(1e3 * z) == 1e-3
    assert infer_unit(1e6 * z) == 1e-6
    assert infer_unit(np.full((5, 3), 0.2)) == 1.0  # still: judged by magnitude
    assert infer_unit(np.full((5, 3), 200.0)) == 1e-3
    assert infer_unit(np.zeros((5, 1))) == 1.0


@pytest.mark.parametrize("name", NAMES)
def test_forecast_error_rms_per_lead_matches_a_direct_computation(name):
    dt, K = 1 / 50, 4
    t = np.arange(int(16 / dt)) * dt
    z = HarmonicSource(f_hz=1.2).position(t)
    z = z + 0.2e-3 * np.random.default_rng(4).standard_normal(z.shape)
    p = make_predictor(name, dt)
    p.ERROR_MEMORY_SECONDS = 1e9  # a plain mean, to compare with the direct RMS
    fc = np.full((t.size, K, 3), np.nan)
    for k in range(t.size):
        p.update(z[k])
        fc[k] = p.predict(K)
    ref = [
        np.sqrt(np.mean(np.sum((fc[: t.size - j - 1, j] - z[j + 1 :]) ** 2, axis=1)))
        for j in range(K)
    ]
    got = p.forecast_error_rms
    assert got.shape == (K,)
    np.testing.assert_allclose(got, ref, rtol=1e-9)
