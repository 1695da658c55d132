"""The cache of fitted models (rhmpc.experiment.model_cache): the same fit is not run twice."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rhmpc.experiment.model_cache import fit_or_load, lookup, model_key, store
from rhmpc.predictors import make_predictor

DT = 0.04


@pytest.fixture
def cache(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Path:
    """A cache of this test's own."""
    monkeypatch.setenv("RHMPC_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("RHMPC_MODEL_CACHE")
    return tmp_path / "cache" / "models"


def series(seed: int = 0, n: int = 400) -> list[np.ndarray]:
    """(n, 1, 3) heart-like samples [m] at 25 Hz, white noise from ``seed``."""
    t = np.arange(n) * DT
    z = 1e-3 * np.stack([np.sin(7.5 * t), np.cos(7.5 * t), np.sin(1.6 * t)], axis=1)
    z += np.random.default_rng(seed).normal(0.0, 2e-5, z.shape)
    return [z[:, None, :]]


def ridge(leads: int = 3):
    """A ridge predictor quick to fit: one window, two penalties to choose from."""
    return make_predictor("ridge", dt=DT, leads=leads, windows=(0.5,), alphas=(1e-5, 1e-3))


def forecasts(p, data: np.ndarray, depth: int) -> np.ndarray:
    """Forecasts of ``depth`` leads after each of the last 50 samples."""
    p.reset()
    out = []
    for i, z in enumerate(data[:, 0]):
        p.update(z)
        if i >= data.shape[0] - 50:
            out.append(p.predict(depth))
    return np.array(out)


def test_the_key_follows_the_samples_the_settings_and_the_period_not_the_leads() -> None:
    base = model_key(ridge(), series())
    assert model_key(ridge(), series()) == base
    assert model_key(ridge(leads=5), series()) == base  # the leads are matched on lookup
    assert model_key(ridge(), series(seed=1)) != base
    assert model_key(make_predictor("ridge", dt=DT, leads=3), series()) != base
    assert model_key(make_predictor("ridge", dt=0.05, leads=3, windows=(0.5,),
                                    alphas=(1e-5, 1e-3)), series()) != base


def test_a_fit_is_kept_and_the_next_one_on_the_same_samples_is_loaded(cache: Path) -> None:
    first = ridge()
    assert fit_or_load(first, series()) is None  # fitted
    (kept,) = cache.iterdir()
    second = ridge()
    assert fit_or_load(second, series()) == kept and second.settings.model == str(kept)
    data = series()[0]
    np.testing.assert_allclose(forecasts(second, data, 3), forecasts(first, data, 3),
                               rtol=0, atol=1e-15)
    assert fit_or_load(ridge(), series(seed=2)) is None  # other samples: fitted again
    assert len(list(cache.iterdir())) == 2


def test_a_model_of_more_leads_serves_fewer_and_not_the_other_way(cache: Path) -> None:
    fit_or_load(ridge(leads=5), series())
    assert lookup(ridge(leads=3), series()) is not None
    assert lookup(ridge(leads=6), series()) is None


def test_a_damaged_model_is_fitted_again(cache: Path) -> None:
    fit_or_load(ridge(), series())
    (kept,) = cache.iterdir()
    kept.write_bytes(b"not a model")
    p = ridge()
    assert fit_or_load(p, series()) is None and p.fitted


def test_the_cache_can_be_turned_off(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("RHMPC_MODEL_CACHE", "off")
    p = ridge()
    assert fit_or_load(p, series()) is None and p.fitted
    assert store(p, series()) is None and not cache.exists()


@pytest.mark.slow
def test_a_closed_loop_run_loads_what_a_run_on_the_same_settling_window_fitted(
        cache: Path) -> None:
    from rhmpc.experiment import RunConfig
    from rhmpc.experiment.assembly import build_run
    from rhmpc.sim.recordings.shipped import SHIPPED

    phantom = SHIPPED["hamlyn-phantom"]
    config = RunConfig(predictor="ridge", data=str(phantom.path), sensor="recorded",
                       data_read={**phantom.read, "point": 4}).replace(
        **{"loop.duration": 8.0, "loop.settling": 6.0})
    first = build_run(config).reference.predictor
    assert first.fitted and first.settings.model is None
    again = build_run(config.replace(seed=3)).reference.predictor  # the same window
    assert again.settings.model is not None and Path(again.settings.model).parent == cache
    for a, b in zip(first.model["W"], again.model["W"], strict=True):
        np.testing.assert_array_equal(a, b)


def test_the_plan_says_which_models_come_from_the_cache() -> None:
    from rhmpc.experiment.fit_plan import FitPlan, describe

    kept = Path("/cache/models/0123-L5.npz")
    lines = describe([FitPlan("ridge", 0, 0.2, None), FitPlan("lstm", 5, 0.2, 0.0, kept)],
                     "frames 0–599 of rec.mat", 600)
    assert lines[0] == "fitting ridge on frames 0–599 of rec.mat"
    assert lines[1] == ("lstm: fitted before on the same samples; loaded from the cache "
                        "(/cache/models), not fitted again")
    assert not any("validation round" in line for line in lines)  # nothing fitted twice
    (only,) = describe([FitPlan("lstm", 5, 0.2, 0.0, kept)], "frames 0–599 of rec.mat", 600)
    assert only.startswith("lstm: fitted before on frames 0–599 of rec.mat; loaded")


def test_the_key_follows_the_code_that_fits(monkeypatch: pytest.MonkeyPatch) -> None:
    from rhmpc.experiment import model_cache

    assert len(model_cache.code_hash("rhmpc.predictors.learned.ridge")) == 16
    before = model_key(ridge(), series())
    monkeypatch.setattr(model_cache, "code_hash", lambda module: "an edited fit")
    assert model_key(ridge(), series()) != before
