"""Horizon weights from forecast confidence (``benchmarks/horizon_weights.py``)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from rhmpc.control.settings import MPCSettings

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from horizon_weights import confidence_weights


def test_weights_follow_the_formula_at_the_predictors_leads() -> None:
    e = np.array([0.1, 0.2, 0.3, 0.4])  # mm at 7.5, 15, 22.5, 30 ms
    w = np.array(confidence_weights(e, 0.0075, 0.0005, 50, sigma=0.1))
    assert w.mean() == pytest.approx(1.0, rel=1e-12)
    raw = 1 / (0.1**2 + e**2)  # ticks 15, 30, 45 are exactly the leads 7.5, 15, 22.5 ms
    np.testing.assert_allclose(w[[14, 29, 44]] / w[14], raw[:3] / raw[0], rtol=1e-12)
    assert np.all(w[:15] == w[0])  # held at the first lead's error before it
    assert np.all(np.diff(w) <= 0)  # less weight where the forecast is less certain


def test_constant_errors_give_uniform_weights_and_the_settings_accept_them() -> None:
    w = confidence_weights([0.2] * 4, 0.0075, 0.0005, 50)
    np.testing.assert_allclose(w, 1.0, rtol=1e-12)
    assert MPCSettings(point_weights=w).point_weights == w


@pytest.mark.parametrize("errors, sigma", [([], None), ([0.1, np.nan], None), ([-1.0], None),
                                           ([0.0, 0.1], None), ([0.1], 0.0)])
def test_bad_errors_are_refused(errors, sigma) -> None:
    with pytest.raises(ValueError):
        confidence_weights(errors, 0.0075, 0.0005, 50, sigma=sigma)
