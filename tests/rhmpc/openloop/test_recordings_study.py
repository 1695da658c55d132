"""Every predictor on a recording, open loop (rhmpc.openloop.recordings): rules and scoring."""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.openloop.plan import OpenLoopSettings, default_predictors, loop_lead, warmup_seconds
from rhmpc.openloop.recordings import run_open_loop
from rhmpc.openloop.scoring import forecast_errors
from rhmpc.openloop.tracks import Track, parse_points
from rhmpc.predictors import make_predictor
from rhmpc.sim.recordings import on_grid


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


@pytest.mark.slow
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


def points_track(T: int = 500, rate: float = 25.0, seed: int = 3) -> Track:
    """Four tracked points of one surface; point 1 is the POI, the others its side
    information."""
    from tests.predictors.helpers import tracked_points

    pts = tracked_points(T, 1.0 / rate, seed=seed, noise=20e-6)
    t = np.arange(T) / rate
    return Track("pts.mat:p1", t, pts[:, 0], "pts.mat", 1, pts[:, 1:])


SPLIT_NAMES = ("hold", "one-step", "st-rls", "ridge", "st-ridge", "combination")


def test_the_split_protocol_fits_before_train_and_scores_train_to_end() -> None:
    track = points_track()
    settings = OpenLoopSettings(predictors=SPLIT_NAMES, leads=4, split=(300, 400))
    doc = run_open_loop([track], settings)
    assert doc["protocol"] == "split" and doc["split"] == [300, 400]
    by = {(r["predictor"], r["lead_samples"]): r for r in doc["results"]}
    assert {r["family"] for r in doc["results"]} == {
        "baseline", "adaptive", "multi-point", "learned", "combination"}
    assert by["st-ridge", 1]["family"] == "learned" and by["st-rls", 1]["family"] == "multi-point"
    assert all(by[n, k]["scored"] == 100 for n in SPLIT_NAMES for k in (1, 4))
    assert by["st-ridge", 1]["fit_s"] is not None and by["one-step", 1]["fit_s"] is None
    assert by["st-rls", 1]["update_us"] > 0
    for k in (1, 2, 3, 4):
        best = min(by[n, k]["rms_error_mm"] for n in SPLIT_NAMES if n != "combination")
        assert by["combination", k]["rms_error_mm"] <= 1.05 * best
        assert by["st-ridge", k]["rms_error_mm"] < by["hold", k]["rms_error_mm"]
    source = doc["sources"][0]
    assert (source["scored_from"], source["scored_to"], source["points"]) == (300, 400, 4)


@pytest.mark.slow
def test_the_split_protocol_never_reads_ahead() -> None:
    """Changing every point from sample m on leaves every error of an origin n with
    n + L < m as it was: neither the fits nor the forecasts read ahead."""
    track = points_track()
    m, L = 340, 4
    rng = np.random.default_rng(0)
    z, others = track.z.copy(), track.others.copy()
    z[m:] += 1e-3 * rng.standard_normal(z[m:].shape)
    others[m:] += 1e-3 * rng.standard_normal(others[m:].shape)
    changed = Track(track.label, track.t, z, track.file, 1, others)
    settings = OpenLoopSettings(predictors=SPLIT_NAMES, leads=L, split=(300, 400))
    from rhmpc.openloop.recordings import score_track

    # errors per origin are not in the rows: score [300, m − L) alone, both ways
    early = OpenLoopSettings(predictors=SPLIT_NAMES, leads=L, split=(300, m - L))
    a = score_track(track, early)[1]
    b = score_track(changed, early)[1]
    assert [r["rms_error_mm"] for r in a] == [r["rms_error_mm"] for r in b]
    c = score_track(changed, settings)[1]
    assert [r["rms_error_mm"] for r in c] != [r["rms_error_mm"] for r in score_track(
        track, settings)[1]]


def test_training_recordings_fit_the_learned_predictors() -> None:
    whole = points_track(800)  # one surface: the first half trains, the second is scored
    series = [whole.points()[:400]]
    track = Track("b.mat:p1", whole.t[400:], whole.z[400:], "b.mat", 1, whole.others[400:])
    doc = run_open_loop([track], OpenLoopSettings(predictors=("hold", "st-ridge", "combination"),
                                                  leads=2, warmup=4.0),
                        train=lambda period: series)
    assert doc["fitted_on"] == "the training recordings" and doc["protocol"] == "online"
    row = next(r for r in doc["results"] if r["predictor"] == "st-ridge")
    assert row["scored"] == 400 - 100 - 1 and row["ratio_to_hold"] < 0.2


def test_fitted_predictors_need_something_to_fit_on_and_splits_are_checked() -> None:
    with pytest.raises(ValueError, match="fitted before the run"):
        run_open_loop([points_track()], OpenLoopSettings(predictors=("st-ridge",), warmup=2.0))
    with pytest.raises(ValueError, match="TRAIN < END"):
        OpenLoopSettings(split=(300, 300))
    with pytest.raises(ValueError, match="no warm-up"):
        OpenLoopSettings(split=(300, 400), warmup=2.0)
    with pytest.raises(ValueError, match="split starts"):
        run_open_loop([points_track(200)], OpenLoopSettings(predictors=("hold",),
                                                            split=(300, 400)))
    names = default_predictors(fitted=True)
    assert names[0] == "hold" and names[-1] == "combination" and "st-ridge" in names
    assert "st-ridge" not in default_predictors()


def test_the_split_says_what_it_fits_on_which_frames_and_how_long_before_fitting() -> None:
    said: list[str] = []
    run_open_loop([points_track()], OpenLoopSettings(predictors=SPLIT_NAMES, leads=2,
                                                    split=(300, 400)), said.append)
    first = said.index(next(s for s in said if s.startswith("fitting ")))
    assert said[first] == ("fitting ridge, st-ridge on frames 0–299 of "
                           f"{points_track().label} (the frames before TRAIN = 300; the "
                           "forecasts issued at frames 300–399 are scored)")
    assert said[first + 1].startswith("about 0 s of fitting") and \
        "ridge about a second; st-ridge about a second" in said[first + 1]
    assert all("TRAIN" not in s for s in said[first + 2:])  # the placeholder is not said
    assert not any(s.startswith("left out") for s in said)  # predictors were given


def test_the_plan_names_the_rounds_their_frames_and_what_the_defaults_leave_out() -> None:
    from rhmpc.experiment.fit_plan import FitPlan, describe

    plans = [FitPlan("ridge", 0, 0.2, None), FitPlan("lstm", 4, 0.2, 95.0),
             FitPlan("tcn", 4, 0.2, 20.0)]
    lines = describe(plans, "frames 0–599 of rec.mat", 600,
                     [FitPlan("gru", 4, 0.2, 400.0), FitPlan("st-gru", 4, 0.2, 410.0)],
                     ["hold", "lstm", "combination"])
    assert lines[0] == "fitting ridge, lstm, tcn on frames 0–599 of rec.mat"
    assert "a validation round on the first 80 % of those frames (0–479), its forecasts on the " \
           "rest (480–599)" in lines[1] and "then the final round on all of them" in lines[1]
    assert lines[2].startswith("about 1.9 min of fitting") and \
        "lstm 1.6 min (4 networks × 2 rounds); tcn 20 s" in lines[2]
    assert lines[3] == ("left out of the default set: gru, st-gru (about 6.7 min and 6.8 min of "
                        "fitting here); add them with --predictors "
                        "hold,lstm,combination,gru,st-gru")


def test_each_network_line_names_its_round() -> None:
    from rhmpc.experiment.fit_plan import FitPlan, _rounds

    said: list[str] = []
    say = _rounds(FitPlan("tcn", 2, 0.2, 1.0), said.append)
    for text in ("network 1/2", "network 2/2", "network 1/2", "network 2/2"):
        say(text)
    assert said == ["fit tcn: validation round, network 1/2",
                    "fit tcn: validation round, network 2/2",
                    "fit tcn: final round, network 1/2", "fit tcn: final round, network 2/2"]


def test_the_defaults_leave_out_the_grus_and_say_so() -> None:
    from rhmpc.openloop.plan import left_out, torch_available

    names = default_predictors(fitted=True)
    assert left_out(names) == (["gru", "st-gru"] if torch_available() else [])
    assert left_out([*names, "gru", "st-gru"]) == []


@pytest.mark.slow
def test_a_network_fit_is_estimated_from_a_probe_of_a_few_epochs() -> None:
    pytest.importorskip("torch")
    from rhmpc.experiment.fit_plan import plan_fits

    track = points_track()
    (plan,) = plan_fits(["tcn"], track.period, [track.points()[:300]], 2, 0)
    assert plan.networks == 2 and plan.rounds == 2  # per-lead heads: one network per lead
    assert plan.estimate_s is not None and plan.estimate_s > 0


def test_the_whole_is_estimated_before_the_first_fit_and_each_scoring_as_it_starts() -> None:
    from rhmpc.openloop.plan import plan_track

    said: list[str] = []
    track = points_track()
    settings = OpenLoopSettings(predictors=SPLIT_NAMES, leads=2, split=(300, 400))
    run_open_loop([track], settings, said.append)
    whole = next(i for i, s in enumerate(said) if s.startswith("about "))
    assert said[whole].startswith("about ") and " in all on 1 track: " in said[whole]
    assert "of fitting" in said[whole] and "of scoring (" in said[whole]
    assert whole < said.index(next(s for s in said if s.startswith("fitting ")))
    for name in SPLIT_NAMES:
        assert any(s.startswith(f"{name} on {track.label} (about ") for s in said), name
    plan = plan_track(track, settings, None)
    assert set(plan.steps) == set(SPLIT_NAMES) - {"ridge", "st-ridge"}  # fitted: not probed
    assert plan.steps["combination"] == sum(plan.steps[n] for n in ("one-step", "st-rls"))
    assert plan.scoring_s() == plan.end * sum(plan.steps.values()) and plan.end == 400
