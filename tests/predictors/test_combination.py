"""The online combination: it follows its best member, per lead, and passes ``others`` on."""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.predictors import make_predictor
from rhmpc.predictors.base import Predictor
from rhmpc.predictors.combination import Combination, CombinationSettings
from tests.predictors.helpers import feed, tracked_points

DT = 0.04


class Noisy(Predictor):
    """Forecasts the true future of ``truth`` plus white noise of σ ``sigma(n)`` [m]."""

    def __init__(self, truth: np.ndarray, sigma, seed: int) -> None:
        self.truth, self.sigma = truth, sigma
        self.rng = np.random.default_rng(seed)
        super().__init__(DT)

    def _update(self, z):
        self.ready = True

    def _predict(self, steps):
        n = self.n - 1  # the newest sample's index
        future = self.truth[n + 1 : n + 1 + steps]
        pad = np.repeat(self.truth[-1:], steps - future.shape[0], axis=0)
        return np.vstack([future, pad]) + self.sigma(n) * self.rng.standard_normal((steps, 3))


def _rms(f: np.ndarray, truth: np.ndarray, lo: int, hi: int, k: int = 1) -> float:
    e = f[lo:hi, k - 1] - truth[lo + k : hi + k]
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


@pytest.mark.slow
def test_it_tracks_the_best_member_of_a_switching_stream() -> None:
    T, switch = 3000, 1500
    truth = tracked_points(T + 8, DT)[:, 0]

    def good_then_bad(n):
        return 10e-6 if n < switch else 100e-6

    def bad_then_good(n):
        return 100e-6 if n < switch else 10e-6

    members = [Noisy(truth, good_then_bad, 1), Noisy(truth, bad_then_good, 2)]
    c = Combination(DT, CombinationSettings(members=("a", "b")), members)
    f = feed(c, truth[:T, None], 2)
    settle = int(2 * c.settings.memory / DT)  # two memories of the discounted errors
    for lo, hi, best in ((settle, switch, 10e-6), (switch + settle, T - 2, 10e-6)):
        for k in (1, 2):
            assert _rms(f, truth, lo, hi, k) < 1.05 * best * np.sqrt(3)
    w = c.weights
    assert w.shape == (2, 4) and np.allclose(w.sum(axis=0), 1.0) and (w[1] > 0.99).all()


def test_near_equal_members_share_the_weight_and_their_errors_cancel() -> None:
    T = 1500
    truth = tracked_points(T + 8, DT)[:, 0]
    members = [Noisy(truth, lambda n: 50e-6, s) for s in (1, 2, 3)]
    c = Combination(DT, CombinationSettings(members=("a", "b", "c")), members)
    f = feed(c, truth[:T, None], 1)
    assert _rms(f, truth, 500, T - 1) < 0.75 * 50e-6 * np.sqrt(3)  # ≈ 1/√3 of each


def test_members_by_name_get_the_other_points_and_the_settings_are_checked() -> None:
    stream = tracked_points(300, DT)
    c = make_predictor("combination", DT, members=("one-step", "st-rls"))
    f = feed(c, stream, 6)
    assert np.isfinite(f).all()
    assert c.members[1].points == 4 and c.members[1].counts["updates"] == 300
    c.reset()
    assert c.members[1].n == 0
    timed = c.member_time.summary()  # each member's update and forecast, against the period
    assert list(timed) == ["one-step", "st-rls"]
    assert all(v["over_period"] <= 300 and v["max_us"] >= 0 for v in timed.values())
    assert c.member_time.n.tolist() == [300, 300]
    with pytest.raises(ValueError, match="members"):
        CombinationSettings(members=("combination",))
    with pytest.raises(ValueError, match="3 names"):
        Combination(DT, CombinationSettings(members=("a", "b", "c")),
                    [make_predictor("hold", DT)])
    with pytest.raises(ValueError, match="exponent"):
        CombinationSettings(exponent=-1.0)


@pytest.mark.slow
def test_scoring_starts_at_score_from_with_the_members_priors() -> None:
    """Before ``score_from`` nothing is scored; there each member's prior error counts: a
    fitted member's validation RMS, an online member's running RMS."""
    stream = tracked_points(700, DT, seed=3)
    fitted = make_predictor("st-ridge", DT).fit(stream[:400])
    s = CombinationSettings(members=("one-step", "st-ridge"), score_from=400)
    c = Combination(DT, s, [make_predictor("one-step", DT), fitted])
    feed(c, stream, 4, upto=400)
    assert (c._count == 0).all() and (c.weights == 0.5).all()
    c._prime()  # what the next update does first
    prior = s.prior_seconds / DT
    np.testing.assert_allclose(c._count, prior)
    online = c.members[0].forecast_error_rms
    np.testing.assert_allclose(c._sq[0], online**2 * prior)
    np.testing.assert_allclose(c._sq[1], (fitted.model["validation_rms"] / fitted.unit) ** 2
                               * prior)


def test_the_default_members_are_the_open_loop_study_s() -> None:
    """Without members, the combination takes every default predictor that is not a baseline,
    the fitted ones included: the same as the open-loop study's combination."""
    from rhmpc.predictors.registry import combination_members, default_predictors, family

    names = combination_members()
    assert names == tuple(n for n in default_predictors(fitted=True)
                          if family(n) not in ("baseline", "combination"))
    assert {"one-step", "st-rls", "ridge", "st-ridge"} <= set(names)
    assert "hold" not in names and "combination" not in names
    assert CombinationSettings().members == ()


def test_members_that_are_not_fitted_take_no_part() -> None:
    """Nothing to fit on: the fitted member (ridge) stays out of the weights and the updates;
    the online ones run and share the weight."""
    stream = tracked_points(300, DT)[:, :1]
    c = make_predictor("combination", DT, members=("one-step", "ridge", "generalized"))
    f = feed(c, stream, 4)
    assert np.isfinite(f).all()
    w = c.weights
    assert np.allclose(w[1], 0.0) and np.allclose(w.sum(axis=0), 1.0)
    assert c.members[1].n == 0 and c.member_time.n.tolist() == [300, 0, 300]
