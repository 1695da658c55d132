"""HeartRateScore against a direct computation on a known estimate sequence."""

import math

import numpy as np
import pytest

from rhmpc.experiment.monitor import HeartRateScore


def test_score_equals_direct_computation() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 30.0, 0.0075)
    true_hz = 1.5 + 0.2 * np.sin(0.3 * t)
    estimate = true_hz + rng.normal(0.0, 0.03, t.size)  # ≈ 1.8 bpm RMS
    estimate[t < 10.0] = math.nan  # an initialisation window
    estimate[(t > 14.0) & (t < 14.1)] += 0.2  # a 12 bpm excursion: unlocked until 14.1 s
    score = HeartRateScore(lambda s: 1.5 + 0.2 * np.sin(0.3 * s), settling=12.0)
    for ti, fi in zip(t, estimate, strict=True):
        score.observe(float(ti), float(fi))
    s = score.summary()
    scored = t >= 12.0
    err = np.abs(60 * (estimate - true_hz))[scored]
    assert s["observations"] == scored.sum()
    assert s["rms_error_bpm"] == pytest.approx(np.sqrt(np.mean(err**2)), rel=1e-12)
    assert s["max_error_bpm"] == pytest.approx(err.max(), rel=1e-12)
    assert s["within_tolerance"] == pytest.approx(np.mean(err < 5.0), rel=1e-12)
    assert s["ready_time_s"] == pytest.approx(t[t >= 10.0][0])
    last_bad = t[np.abs(60 * (estimate - true_hz)) >= 5.0][-1]
    assert s["lock_time_s"] == pytest.approx(t[t > last_bad][0])


def test_never_ready_reports_no_observations() -> None:
    score = HeartRateScore(lambda s: 1.0)
    score.observe(1.0, math.nan)
    assert score.summary() == {"observations": 0}
