"""Several tracked points: the ``others`` of the contract, the spatio-temporal RLS, the ridge
regressions, and causality (no forecast reads a sample at or after the instants it forecasts)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from rhmpc.predictors import family, make_predictor
from rhmpc.predictors.combination import Combination, CombinationSettings
from tests.predictors.helpers import feed, tracked_points

DT = 0.04  # 25 frames/s, the stereo trackers' rate


def _fitted(name: str, stream: np.ndarray, **kw):
    p = make_predictor(name, DT, **kw)
    return p.fit(stream) if hasattr(p, "fit") else p


def test_others_are_checked_and_ignored_by_a_single_point_predictor() -> None:
    stream = tracked_points(60, DT)
    hold = make_predictor("hold", DT)
    hold.update(stream[0, 0], np.zeros((7, 2)))  # not read: no check
    p = make_predictor("st-rls", DT)
    p.update(stream[0, 0], stream[0, 1:])
    assert p.points == 4
    with pytest.raises(ValueError, match="expected \\(3, 3\\)"):
        p.update(stream[1, 0], stream[1, 1:3])
    with pytest.raises(ValueError, match="others has shape"):
        p.update(stream[1, 0], stream[1, 1:].reshape(-1))
    p.update(stream[1, 0], None)  # the others missing: NaN rows
    bad = stream[2, 1:].copy()
    bad[0, 1], bad[1, 0] = np.nan, 1e200  # a NaN, an overflowing square: those points missing
    p.update(stream[2, 0], bad)
    assert p.counts["others_missing"] == 3 + 2
    assert np.isfinite(p.predict(3)).all()


def test_families() -> None:
    assert [family(n) for n in ("hold", "one-step", "st-rls", "st-ridge", "combination")] == [
        "baseline", "adaptive", "multi-point", "learned", "combination"]


MIXING = np.array([[0.5, -0.2, 0.1], [0.3, 0.8, 0.0], [-0.4, 0.1, 0.6]])


@pytest.mark.parametrize(("name", "settings", "A"), [
    ("st-rls", {"correlated": True, "forgetting_factor": 1.0}, MIXING),
    ("st-rls", {"forgetting_factor": 1.0}, np.diag([0.5, -0.8, 0.6])),  # axis by axis
    ("st-ridge", {}, MIXING),
])
@pytest.mark.slow
def test_recovers_an_exactly_linear_cross_point_relation(name: str, settings: dict,
                                                         A: np.ndarray) -> None:
    """z_n = A o_{n−1}: the POI is another point's previous sample mapped by A, and that point
    is white noise, so only the other point's present tells the POI's next sample."""
    rng = np.random.default_rng(3)
    T = 700
    o = 1e-3 * rng.standard_normal((T, 2, 3))  # two other points, white [m]
    z = np.zeros((T, 3))
    z[1:] = o[:-1, 0] @ A.T
    stream = np.concatenate([z[:, None], o], axis=1)
    if name == "st-ridge":
        p = _fitted(name, stream[:500], unit=1.0)
    else:
        p = make_predictor(name, DT, unit=1.0, **settings)
    f = feed(p, stream, 1)
    miss = np.linalg.norm(f[550:-1, 0] - z[551:], axis=1)
    poi_only = make_predictor("one-step", DT, unit=1.0)
    g = feed(poi_only, stream[:, :1], 1)
    blind = np.linalg.norm(g[550:-1, 0] - z[551:], axis=1)
    assert np.sqrt(np.mean(miss**2)) < 1e-3 * np.sqrt(np.mean(blind**2))


def _leak_check(make, stream: np.ndarray, cut: int, steps: int = 4) -> None:
    """Forecasts issued before ``cut`` are the same when every point's samples from ``cut`` on
    are changed (bit for bit)."""
    changed = stream.copy()
    rng = np.random.default_rng(1)
    changed[cut:] += 2e-3 * rng.standard_normal(changed[cut:].shape)
    changed[cut + 3, 2] = np.nan
    a = feed(make(), stream, steps, upto=cut + 10)
    b = feed(make(), changed, steps, upto=cut + 10)
    np.testing.assert_array_equal(a[:cut], b[:cut])
    assert not np.array_equal(a[cut : cut + 10], b[cut : cut + 10])


@pytest.mark.parametrize("name", ["st-rls", "ridge", "st-ridge", "combination"])
@pytest.mark.slow
def test_no_forecast_reads_a_sample_at_or_after_the_instants_it_forecasts(name: str) -> None:
    stream = tracked_points(420, DT, seed=2)
    fitted = {n: _fitted(n, stream[:300]) for n in ("ridge", "st-ridge")}
    if name == "combination":
        def make():
            members = [make_predictor("st-rls", DT), copy.deepcopy(fitted["st-ridge"]),
                       make_predictor("one-step", DT)]
            s = CombinationSettings(members=("st-rls", "st-ridge", "one-step"))
            return Combination(DT, s, members)
    elif name in fitted:
        def make():
            return copy.deepcopy(fitted[name])
    else:
        def make():
            return make_predictor(name, DT)
    for cut in (330, 401):
        _leak_check(make, stream, cut)


def test_st_rls_runs_through_gaps_of_any_point_and_retracts_the_poi_only() -> None:
    stream = tracked_points(900, DT, seed=4)
    stream[500:520, 0] = np.nan  # the POI lost
    stream[600:640, 1:3] = np.nan  # two other points lost
    p = make_predictor("st-rls", DT)
    f = feed(p, stream, 4)
    assert np.isfinite(f).all()
    assert p.counts["missing"] == 20 and p.counts["others_missing"] == 80
    assert p.counts["repaired"] >= 1
    truth = stream[:, 0]
    late = np.linalg.norm(f[700:-1, 0] - truth[701:], axis=1)
    assert np.sqrt(np.mean(late**2)) < 0.1e-3
    others_before = p.line.buf[0, 3:].copy()
    assert p.retract()
    np.testing.assert_array_equal(p.line.buf[0, 3:], others_before)  # measured: untouched


def test_reset_keeps_the_number_of_points_and_a_lone_sample_after_it_is_taken() -> None:
    """The reference's restart: reset, then the last sample alone, then the stream again."""
    stream = tracked_points(80, DT)
    p = make_predictor("st-rls", DT)
    feed(p, stream[:40], 2)
    p.reset()
    p.update(stream[40, 0])  # no others: they are missing for this sample
    assert p.points == 4 and p.counts["others_missing"] == 3
    feed(p, stream[41:], 2)
    assert np.isfinite(p.predict(2)).all()
