"""The non-periodic part of the Fourier predictors, last-cycle's breathing removal, the
papers' parameter sets by name."""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.predictors import make_predictor, settings_for
from rhmpc.predictors.nonperiodic import NonPeriodic, long_run_variance
from rhmpc.predictors.residual import ResidualAR


def _ar2(rng: np.random.Generator, n: int, a1: float, a2: float) -> np.ndarray:
    e = np.zeros(n)
    w = rng.standard_normal(n)
    for k in range(2, n):
        e[k] = a1 * e[k - 1] + a2 * e[k - 2] + w[k]
    return e


def test_residual_ar_learns_an_ar2_process() -> None:
    """e_n = 1.6 e_{n−1} − 0.8 e_{n−2} + w: RLS finds (1.6, −0.8), and b for an input u the
    residual follows with weight 0.5."""
    rng = np.random.default_rng(3)
    e = _ar2(rng, 4000, 1.6, -0.8)
    u = rng.standard_normal(e.size)
    e = e + 0.5 * u
    model = ResidualAR(1, 2, 1.0, 1e-6)
    for n in range(3, len(e)):
        # the input's part of e_n is known, so the lags are those of the AR(2) part
        lags = e[n - 2 : n][::-1] - 0.5 * u[n - 2 : n][::-1]
        model.learn(np.concatenate([[e[n]], lags])[:, None], u[n : n + 1])
    assert model.rls.W[0, 0] == pytest.approx([1.6, -0.8, 0.5], abs=0.03)


def test_residual_ar_starts_as_persistence_and_replaces_a_wild_forecast() -> None:
    model = ResidualAR(2, 3, 0.999, 1e-8)
    e = np.array([[0.3, -0.1], [0.2, 0.0], [0.1, 0.1], [0.0, 0.2]])
    assert model.forecast(e, np.zeros((4, 2)), 4) == pytest.approx(np.tile(e[0], (4, 1)))
    model.rls.W[0, 0, :3] = [3.0, 0.0, 0.0]  # an explosive fit on axis 0
    out = model.forecast(e, np.zeros((4, 2)), 4)
    assert out[:, 0] == pytest.approx(np.full(4, 0.3)) and model.rls.counts["residual_unstable"]


def test_long_run_variance_of_an_ar1() -> None:
    rng = np.random.default_rng(4)
    rho, n = 0.8, 200_000
    e = np.zeros(n)
    w = rng.standard_normal(n)
    for k in range(1, n):
        e[k] = rho * e[k - 1] + w[k]
    expected = np.var(e) * (1 + rho) / (1 - rho)
    assert long_run_variance(e[:, None])[0] == pytest.approx(expected, rel=0.05)


@pytest.mark.parametrize("deviation", [0.0, 0.5e-3])
def test_r_follows_the_residual_of_the_model_over_a_beat(deviation: float) -> None:
    """A model that explains the motion leaves R̂ at the floor; a smooth deviation of 0.5 mm
    the model does not hold raises it above 0.5 mm (its long-run variance)."""
    dt, f = 0.04, 1.0
    t = np.arange(1500) * dt
    rng = np.random.default_rng(5)
    slow = np.convolve(rng.standard_normal(t.size + 40), np.hanning(40), "valid")[: t.size]
    dev = deviation * slow / np.std(slow)
    z = 2e-3 * np.sin(2 * np.pi * f * t) + dev
    floor = (0.1e-3) ** 2
    part = NonPeriodic(1, dt, floor, True, 0, 0.999, 1.0, 0.5, None)
    for n in range(t.size):
        part.push(z[n : n + 1])

        def model(k, n=n):
            return 2e-3 * np.sin(2 * np.pi * f * (t[n] + k * dt))[:, None]

        part.follow(model, 2 * np.pi * f, np.zeros(1), learn=n > 100)
    if deviation:
        assert np.sqrt(part.r[0]) > deviation
    else:
        assert part.r[0] == pytest.approx(floor)


def test_anchored_last_cycle_removes_the_breathing_offset() -> None:
    """Heart at 1.2 Hz on 0.2 Hz breathing 3× its size: the anchored cycle is 1-step error a
    fraction of the plain one's (which carries a period's breathing change)."""
    dt = 0.04
    t = np.arange(1500) * dt
    z = (np.sin(2 * np.pi * 1.2 * t) + 3 * np.sin(2 * np.pi * 0.2 * t))[:, None] * 1e-3
    err = {}
    for params in ("anchored", "yuen2008"):
        p = make_predictor("last-cycle", dt, params=params)
        e = []
        for n in range(len(z) - 1):
            p.update(z[n])
            if n > 300:
                e.append(abs(p.predict(1)[0, 0] - z[n + 1, 0]))
        err[params] = np.sqrt(np.mean(np.square(e)))
    assert err["anchored"] < 0.3 * err["yuen2008"]


def test_the_papers_parameter_sets_by_name() -> None:
    yuen = settings_for("ekf", params="yuen2008")
    assert (yuen.harmonics, yuen.breathing_harmonics) == (8, 0)
    assert yuen.sigma_r == pytest.approx(1.3e-3)
    assert not yuen.adaptive_r and not yuen.residual_order
    tuna = settings_for("ekf", params="tuna2013")
    assert (tuna.q_omega, tuna.sigma_r, tuna.fit_beats) == (5e-3, 0.3e-3, 0)
    richa = settings_for("dual-ekf", params="richa2010")
    assert richa.init_seconds is None and richa.gate_probability is None
    assert not settings_for("last-cycle", params="yuen2008").anchored
    assert settings_for("wflc", params="yuen2009").loop == "gradient"
    for name in ("ekf", "dual-ekf", "wflc"):
        assert settings_for(name).residual_order == 16
    assert settings_for("last-cycle").anchored


@pytest.mark.parametrize(("name", "setting"), [
    ("ekf", {"residual_order": -1}), ("ekf", {"rate_band": 0.9}),
    ("dual-ekf", {"fit_beats": 1.5}), ("wflc", {"loop_ratio": 0.0}),
    ("wflc", {"weight_beats": -2.0}),
])
def test_bad_settings_are_refused(name: str, setting: dict) -> None:
    with pytest.raises(ValueError):
        make_predictor(name, 0.04, **setting)
