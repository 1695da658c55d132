"""Every predictor on the `Predictor` contract: shapes, missing samples, dropouts, registry."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from rhmpc.predictors import PREDICTORS, Predictor, make_predictor
from rhmpc.predictors.monitor import rms_by_lead
from tests.predictors.helpers import HarmonicSource, each

DT = 0.0075
SRC = HarmonicSource(f_hz=1.2)


def _make(name, dt=DT, **kw):
    if name == "exact":
        kw.setdefault("source", SRC)
    return make_predictor(name, dt, **kw)


@pytest.mark.parametrize("name", each(PREDICTORS))
def test_shapes_reset_and_missing_kinds(name):
    p = _make(name)
    assert isinstance(p, Predictor)
    z = SRC.position(np.arange(50) * DT)
    for zk in z:
        p.update(zk)
    assert p.predict(4).shape == (4, 3)
    assert p.predict(1).shape == (1, 3)
    before = p.counts["missing"]
    p.update(None)
    p.update([np.nan, 0.0, 0.0])
    p.update(np.array([0.0, np.inf, 0.0]))
    p.update(np.full(3, 1e200))  # finite, but its squared norm overflows: no measurement
    assert p.counts["missing"] == before + 4
    assert np.isfinite(p.predict(4)).all()
    with pytest.raises(ValueError):
        p.update(np.zeros(2))  # wrong dimension is a wiring bug, not a dropout
    with pytest.raises(ValueError):
        p.predict(0)
    p.reset()
    assert p.n == 0 and not p.counts


@pytest.mark.parametrize("name", each(n for n in PREDICTORS if n != "exact"))
def test_predict_before_any_sample_raises(name):
    p = _make(name)
    with pytest.raises(RuntimeError):
        p.predict(4)


@pytest.mark.parametrize("name", each(PREDICTORS))
@pytest.mark.slow
def test_one_second_dropout_stays_finite_and_recovers_within_two_seconds(name):
    """20 s of data, 1 s without samples, then 4 s: the 4-step error 2–4 s after the gap is back."""
    dt = DT if name not in ("wflc", "ar", "fading-ar") else 1 / 28  # tuned at the 3DUS rate
    t = np.arange(int(25 / dt)) * dt
    truth = SRC.position(t)
    rng = np.random.default_rng(10)
    z = truth + 20e-6 * rng.standard_normal(truth.shape)
    gap = (t >= 20.0) & (t < 21.0)
    p = _make(name, dt)
    K = 4
    err = np.full(t.size, np.nan)
    for k in range(t.size):
        p.update(None if gap[k] else z[k])
        f = p.predict(K)
        assert np.isfinite(f).all(), f"non-finite forecast at t={t[k]:.3f}"
        if k + K < t.size:
            err[k] = np.linalg.norm(f[-1] - truth[k + K])
    assert p.counts["missing"] == gap.sum()
    before = np.sqrt(np.nanmean(err[(t >= 17) & (t < 20)] ** 2))
    after = np.sqrt(np.nanmean(err[(t >= 23) & (t < 24.9)] ** 2))
    assert after <= 1.5 * before + 30e-6, (before, after)


def test_registry_rejects_bad_names_and_settings():
    with pytest.raises(ValueError, match="valid: one-step"):
        make_predictor("kalman", DT)
    with pytest.raises(ValueError, match="order"):
        make_predictor("one-step", DT, ordr=3)
    with pytest.raises(ValueError, match="yuen2008"):
        make_predictor("ekf", DT, params="nope")
    with pytest.raises(ValueError, match="params"):
        make_predictor("hold", DT, params="tuna2013")
    with pytest.raises(ValueError, match="forgetting_factor"):
        make_predictor("generalized", DT, forgetting_factor=1.5)
    with pytest.raises(ValueError, match="harmonics"):
        make_predictor("ekf", DT, harmonics=0)
    with pytest.raises(ValueError, match="source"):
        make_predictor("exact", DT)
    with pytest.raises(ValueError, match="dt"):
        make_predictor("hold", 0.0)


@pytest.mark.parametrize("name, bad, message", [
    ("ekf", {"harmonics": 1.5}, "harmonics must be an integer >= 1"),
    ("ekf", {"breathing_harmonics": -1}, "breathing_harmonics must be an integer >= 0"),
    ("ekf", {"q_omega_per_second": -1.0}, "q_omega_per_second must be >= 0 or None"),
    ("ekf", {"band_hz": (3.0, 0.6)}, "band_hz must be"),
    ("ekf", {"gate_probability": 1.0}, "gate_probability"),
    ("ekf", {"rate_band": 0.9}, "rate_band must be > 1"),
    ("dual-ekf", {"cardiac_harmonics": 0}, "cardiac_harmonics must be an integer >= 1"),
    ("dual-ekf", {"q_omega_respiratory": -1.0}, "q_omega_respiratory must be >= 0 or None"),
    ("dual-ekf", {"init_seconds": 0.0}, "init_seconds must be > 0 or None"),
    ("dual-ekf", {"cardiac_band_hz": (0.0, 3.0)}, "cardiac_band_hz must be"),
    ("dual-ekf", {"residual_forgetting": 0.0}, "residual_forgetting"),
    ("dual-ekf", {"fit_beats": -2}, "fit_beats must be an integer >= 0"),
])
def test_fourier_settings_reject_values_out_of_range(name, bad, message):
    with pytest.raises(ValueError, match=message):
        make_predictor(name, DT, **bad)


@pytest.mark.parametrize("name", each(PREDICTORS))
def test_a_setting_given_a_table_names_its_key(name):
    """``predictor_settings.KEY = { … }`` for every setting of every predictor: a ValueError
    naming the key, before any arithmetic meets the table."""
    from rhmpc.predictors.registry import settings_for

    base = {"source": SRC} if name == "exact" else {}
    for f in dataclasses.fields(settings_for(name, **base)):
        if f.name in base:
            continue  # the true future's source: any object with position(t)
        with pytest.raises(ValueError, match=rf"^{f.name} must be .*, got a table"):
            settings_for(name, **base, **{f.name: {"a": 1}})


def test_registry_presets_and_overrides():
    assert make_predictor("ekf", DT).settings.harmonics == 5  # tuna2013 by default
    e = make_predictor("ekf", DT, params="yuen2008", sigma_r=1e-3)
    assert e.settings.harmonics == 8 and e.settings.sigma_r == 1e-3
    assert make_predictor("fading-ar", DT).settings.forgetting_factor == 0.985
    assert make_predictor("ar", DT).settings.forgetting_factor == 1.0


def test_exact_reads_the_future_and_follows_set_time():
    p = make_predictor("exact", DT, source=SRC, t0=1.0)
    np.testing.assert_allclose(p.predict(2), SRC.position(1.0 + DT * np.arange(2)))
    for _ in range(10):
        p.update(None)
    assert p.time == pytest.approx(1.0 + 9 * DT)
    np.testing.assert_allclose(p.predict(3), SRC.position(1.0 + DT * np.arange(10, 13)))
    p.set_time(5.0)
    np.testing.assert_allclose(p.predict(1)[0], SRC.position(5.0 + DT))


def test_hold_repeats_the_last_valid_sample():
    p = make_predictor("hold", DT)
    p.update([1.0, 2.0, 3.0])
    p.update(None)
    np.testing.assert_array_equal(p.predict(3), [[1.0, 2.0, 3.0]] * 3)


def test_last_cycle_period_from_signal_and_from_rr():
    dt = 1 / 28
    t = np.arange(int(12 / dt)) * dt
    z = SRC.position(t)
    p = make_predictor("last-cycle", dt)
    for zk in z:
        p.update(zk)
    assert p.period * dt == pytest.approx(1 / 1.2, rel=0.01)
    beats = tuple(np.arange(0.0, 13.0, 1 / 1.2))
    q = make_predictor("last-cycle", dt, beat_times=beats)
    for zk in z:
        q.update(zk)
    assert q.period * dt == pytest.approx(1 / 1.2)
    np.testing.assert_allclose(
        q.predict(3), SRC.position(t[-1] + dt * np.arange(1, 4)), atol=0.3e-3
    )


def test_caller_buffers_are_not_kept_by_reference():
    p = make_predictor("hold", DT)
    buf = np.array([1.0, 2.0, 3.0])
    p.update(buf)
    buf[:] = 0.0
    np.testing.assert_array_equal(p.predict(1)[0], [1.0, 2.0, 3.0])


def test_rms_by_lead_scores_hold_on_a_ramp_exactly():
    # hold forecasts z_n at every lead; on z_n = v·n (3-D) its miss at lead k is k‖v‖ exactly
    v = np.array([1e-4, -2e-4, 3e-4])
    z = np.arange(200)[:, None] * v
    rms = rms_by_lead(make_predictor("hold", DT), z, 4, 50)
    np.testing.assert_allclose(rms, np.arange(1, 5) * np.linalg.norm(v), rtol=1e-12)


# -- the predictors fitted before the run -------------------------------------------------
FITTED = {"ridge": {}, "st-ridge": {}, "lstm": {"hidden": 8, "epochs": 5, "validation": 0.0},
          "st-tcn": {"channels": 4, "dilations": (1, 2), "epochs": 5, "validation": 0.0}}
DT_VIDEO = 0.04


def _fitted(name):
    if name in ("lstm", "st-tcn"):
        pytest.importorskip("torch", reason="the neural predictors need PyTorch (rhmpc[learned])")
    p = make_predictor(name, DT_VIDEO, **FITTED[name])
    return p.fit(SRC.position(np.arange(500) * DT_VIDEO))


@pytest.mark.parametrize("name", list(FITTED))
@pytest.mark.slow
def test_fitted_predictors_keep_the_contract(name):
    p = _fitted(name)
    with pytest.raises(RuntimeError):
        p.predict(4)
    z = SRC.position(np.arange(500, 600) * DT_VIDEO)
    for zk in z[:80]:
        p.update(zk)
    assert p.predict(4).shape == (4, 3) and p.predict(9).shape == (9, 3)
    before = p.counts["missing"]
    for bad in (None, [np.nan, 0.0, 0.0], np.array([0.0, np.inf, 0.0]), np.full(3, 1e200)):
        p.update(bad)
    assert p.counts["missing"] == before + 4 and np.isfinite(p.predict(4)).all()
    with pytest.raises(ValueError):
        p.update(np.zeros(2))
    model = p.model
    p.reset()
    assert p.n == 0 and not p.counts and p.model is model  # the fitted model stays
    for zk in z:
        p.update(zk)
    assert p.ready and np.isfinite(p.predict(4)).all()


@pytest.mark.parametrize("name", list(FITTED))
@pytest.mark.slow
def test_fitted_predictors_bridge_a_one_second_dropout(name):
    p = _fitted(name)
    t = np.arange(500, 1000) * DT_VIDEO
    truth = SRC.position(t)
    gap = (t >= t[250]) & (t < t[275])
    err = np.full(t.size, np.nan)
    for k in range(t.size):
        p.update(None if gap[k] else truth[k])
        f = p.predict(4)
        assert np.isfinite(f).all()
        if k + 4 < t.size:
            err[k] = np.linalg.norm(f[-1] - truth[k + 4])
    before = np.sqrt(np.nanmean(err[150:250] ** 2))
    after = np.sqrt(np.nanmean(err[325:490] ** 2))
    assert after <= 1.5 * before + 30e-6, (before, after)
