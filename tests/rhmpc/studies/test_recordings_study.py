"""Every predictor on a recording, open loop (rhmpc.studies.recordings): rules and scoring."""

from __future__ import annotations

import numpy as np
import pytest

from predictors import make_predictor
from rhmpc.studies.recordings import (
    OpenLoopSettings,
    Track,
    default_predictors,
    forecast_errors,
    loop_lead,
    on_grid,
    parse_points,
    run_open_loop,
    warmup_seconds,
)


def motion(rate: float, seconds: float, seed: int = 1, noise: float = 1e-4) -> Track:
    """Heart 1.2 Hz and breathing 0.25 Hz in 3-D [m], white noise σ per axis."""
    t = np.arange(0.0, seconds, 1.0 / rate)
    ph = 2 * np.pi * 1.2 * t
    b = 2 * np.pi * 0.25 * t
    z = 1e-3 * np.stack([1.5 * np.sin(ph) + 2 * np.sin(b), np.cos(ph) + 0.8 * np.sin(b),
                         2 * np.sin(ph + 0.5) + 1.5 * np.sin(b + 0.6)], 1)
    z += np.random.default_rng(seed).normal(0.0, noise, z.shape)
    return Track(f"rec{rate:g}", t, z, f"rec{rate:g}.csv")


@pytest.mark.parametrize(("rate", "latency", "expected"), [
    (25.0, 0.0, 2), (30.0, 0.0, 2), (257.0, 0.0, 8), (404.0, 0.0, 12), (25.0, 0.040, 3),
    (2000.0, 0.0, 51),
])
def test_loop_lead_rule(rate: float, latency: float, expected: int) -> None:
    """K_loop = ⌈(Δ + λ + 25 ms)/Δ⌉, also where the quotient is an integer (2 kHz: 51)."""
    assert loop_lead(1.0 / rate, latency, 0.025) == expected


def test_warmup_rule() -> None:
    assert warmup_seconds(20.0, None) == 10.0
    assert warmup_seconds(60.0, None) == 15.0
    assert warmup_seconds(60.0, 2.5) == 2.5


def test_scores_match_a_direct_run_and_the_rows_are_complete() -> None:
    track = motion(25.0, 16.0)
    doc = run_open_loop([track], OpenLoopSettings(leads=3, warmup=4.0))
    assert doc["rate_hz"] == pytest.approx(25.0) and doc["warmup_s"] == 4.0
    names = default_predictors()
    assert names[:2] == ("hold", "last-cycle") and "exact" not in names
    assert {(r["predictor"], r["lead_samples"]) for r in doc["results"]} == {
        (n, k) for n in names for k in (1, 2, 3)}  # K_loop = 2 is among them
    # the one-step row, recomputed by hand: the predictor sees each sample once at 25 Hz
    p = make_predictor("one-step", dt=0.04)
    err = []
    for n in range(track.t.size - 1):
        p.update(track.z[n])
        if n >= 100:
            err.append(np.linalg.norm(p.predict(1)[0] - track.z[n + 1]))
    row = next(r for r in doc["results"]
               if r["predictor"] == "one-step" and r["lead_samples"] == 1)
    assert row["rms_error_mm"] == pytest.approx(1e3 * np.sqrt(np.mean(np.square(err))))
    assert row["scored"] == len(err)
    hold = next(r for r in doc["results"] if r["predictor"] == "hold" and r["lead_samples"] == 1)
    assert row["ratio_to_hold"] == pytest.approx(row["rms_error_mm"] / hold["rms_error_mm"])
    assert row["ratio_to_hold"] < 0.5 and hold["ratio_to_hold"] == 1.0
    assert [r["loop_lead"] for r in doc["results"][:3]] == [False, True, False]
    assert doc["sources"][0]["loop_lead_samples"] == 2


def test_missing_samples_and_gaps_are_fed_as_missing_and_not_scored() -> None:
    track = motion(30.0, 14.0)
    z = track.z.copy()
    z[200:203] = np.nan  # dropouts
    keep = np.ones(track.t.size, dtype=bool)
    keep[300:305] = False  # a gap in the timestamps
    t_grid, z_grid = on_grid(track.t[keep], z[keep], 1 / 30.0)
    assert t_grid.size == track.t.size and np.isnan(z_grid[300:305]).all()
    errors, counts = forecast_errors("generalized", z_grid, 1 / 30.0, 120, 2)
    assert counts["missing"] == 8
    assert np.isnan(errors[199:202, 0]).all() and np.isnan(errors[299:304, 0]).all()
    assert np.isfinite(errors[205:295, :]).all()
    doc = run_open_loop([Track("gappy", track.t[keep], z[keep])],
                        OpenLoopSettings(predictors=("hold", "generalized"), warmup=4.0))
    assert doc["sources"][0]["gap_samples"] == 5 and doc["sources"][0]["missing"] == 8
    assert all(r["missing"] == 8 for r in doc["results"])


def test_points_are_scored_with_their_mean() -> None:
    points = [motion(25.0, 14.0, seed=s) for s in (1, 2)]
    points = [Track(f"p.mat:p{k + 1}", p.t, p.z, "p.mat", k + 1) for k, p in enumerate(points)]
    doc = run_open_loop([points], OpenLoopSettings(predictors=("hold", "one-step"), leads=2,
                                                   warmup=3.0))
    by = {(r["source"], r["predictor"], r["lead_samples"]): r for r in doc["results"]}
    mean = by["p.mat:mean", "one-step", 1]
    each = [by[f"p.mat:p{k}", "one-step", 1]["rms_error_mm"] for k in (1, 2)]
    assert mean["rms_error_mm"] == pytest.approx(np.mean(each)) and mean["points"] == 2
    assert [s["label"] for s in doc["sources"]] == ["p.mat:p1", "p.mat:p2"]


def test_bad_settings_and_a_recording_too_short() -> None:
    with pytest.raises(ValueError, match="unknown predictor"):
        OpenLoopSettings(predictors=("exact",))
    with pytest.raises(ValueError, match="leads"):
        OpenLoopSettings(leads=0)
    with pytest.raises(ValueError, match="leave nothing to score"):
        run_open_loop([motion(25.0, 8.0)], OpenLoopSettings(predictors=("hold",)))
    assert parse_points("all") == "all" and parse_points("1,3") == (1, 3)
    assert parse_points(None) is None
    with pytest.raises(ValueError, match="--points"):
        parse_points("0")
