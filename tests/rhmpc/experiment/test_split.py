"""A recording in closed loop: scored at its measured instants, and the literature's split
(``split`` = (TRAIN, END)): the loop from the first sample, the fitted predictors on the samples
before TRAIN, the score on the instants of [TRAIN, END)."""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.cli import main
from rhmpc.errors import UsageError
from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.experiment.assembly import build_run
from rhmpc.experiment.config import with_split
from rhmpc.sim.recordings.shipped import SHIPPED

PHANTOM = SHIPPED["hamlyn-phantom"]


def _config(predictor: str = "hold", **changes) -> RunConfig:
    return RunConfig(predictor=predictor, data=str(PHANTOM.path),
                     data_read={**PHANTOM.read, "point": 4}, sensor="recorded").replace(**changes)


def test_the_split_sets_the_settling_and_the_duration():
    c = with_split(_config(), (100, 200))
    assert (c.loop.settling, c.loop.duration) == (4.0, 8.0)  # samples 100 … 199 at 25 Hz
    c = with_split(_config(), (600, 750))  # to the end: n/f, the last frame's period
    assert (c.loop.settling, c.loop.duration) == (24.0, 30.0)
    with pytest.raises(UsageError, match="holds 750 samples"):
        with_split(_config(), (600, 751))
    with pytest.raises(UsageError, match="needs --data"):
        with_split(RunConfig(), (1, 2))


def test_a_recording_is_scored_at_its_measured_instants():
    """rms_error_mm is the tool against each sample of [TRAIN, END) at its instant, computed
    again here from the result's trace (which keeps the ticks at the instants) and samples;
    the all-tick score against the samples' interpolant is the second figure."""
    result, doc = run_experiment(with_split(_config(), (150, 250)))
    assert doc["score"] == "measured" and doc["scored_samples"] == 100
    t, p, scored = result.measured
    assert scored.sum() == 100 and np.flatnonzero(scored).tolist() == list(range(150, 250))
    rows = np.searchsorted(result.time, t[scored] - 1e-9)
    np.testing.assert_allclose(result.time[rows], t[scored], atol=1e-12)
    e = np.linalg.norm(result.ee[rows] - p[scored], axis=1)
    np.testing.assert_allclose(doc["rms_error_mm"], 1e3 * np.sqrt(np.mean(e**2)), rtol=1e-12)
    np.testing.assert_allclose(doc["max_error_mm"], 1e3 * e.max(), rtol=1e-12)
    from rhmpc.report.figures import measured_errors  # what the figures draw

    t_fig, e_fig = measured_errors(result)
    np.testing.assert_allclose(t_fig, t[scored])
    np.testing.assert_allclose(np.sqrt(np.mean(e_fig**2)), doc["rms_error_mm"], rtol=1e-12)
    assert np.isfinite(doc["rms_error_interpolated_mm"])
    assert doc["rms_error_interpolated_mm"] != doc["rms_error_mm"]


def test_a_synthetic_motion_keeps_its_every_tick_score():
    _, doc = run_experiment(RunConfig(predictor="hold").replace(
        **{"loop.duration": 1.0, "loop.settling": 0.5}))
    assert doc["score"] == "continuous" and "rms_error_interpolated_mm" not in doc


def test_a_combination_scores_its_members_after_the_samples_they_learnt():
    run = build_run(with_split(_config("combination", predictor_settings={
        "members": ["one-step", "ridge"]}), (100, 150)))
    combination = run.reference.predictor
    assert combination.fitted and combination.members[1].fitted
    assert combination.settings.score_from == 100  # the refreshes before TRAIN


def test_the_split_on_the_command_line(capsys):
    args = ["simulate", "--data", "hamlyn-phantom", "--predictor", "hold"]
    assert main([*args, "--split", "600:750", "--settling", "3"]) == 2
    assert "give neither --settling nor --duration" in capsys.readouterr().err
    assert main([*args, "--split", "7"]) == 2
    assert "expected TRAIN:END" in capsys.readouterr().err
    assert main(["simulate", "--split", "1:2"]) == 2
    assert "need --data" in capsys.readouterr().err


def test_fit_once_run_many(tmp_path):
    """Models saved by predict --save-models load in the closed loop: the run fits nothing
    (its model is the file's, whatever the settling window holds)."""
    from rhmpc.experiment.fitting import with_models
    from rhmpc.predictors.registry import load_model

    assert main(["predict", "--data", "hamlyn-phantom", "--poi", "4", "--split", "100:150",
                 "--predictors", "ridge", "--save-models", str(tmp_path / "m")]) == 0
    (model,) = sorted((tmp_path / "m").iterdir())
    saved = load_model(model, "ridge", dt=0.04)
    loaded = build_run(with_models(with_split(_config("ridge"), (300, 350)), [model]))
    predictor = loaded.reference.predictor
    assert predictor.settings.model == str(model) and predictor.fitted
    for a, b in zip(saved.model["W"], predictor.model["W"], strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)
    combination = build_run(with_models(with_split(_config(
        "combination", predictor_settings={"members": ["one-step", "ridge"]}), (100, 150)),
        [model]))
    assert combination.reference.predictor.members[1].settings.model == str(model)
    with pytest.raises(UsageError, match="one-step is not fitted before the run"):
        with_models(_config("one-step"), [model])
    assert with_models(_config("one-step"), [model], strict=False).predictor_settings == {}
