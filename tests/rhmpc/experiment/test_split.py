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
from sim.recordings.shipped import SHIPPED

PHANTOM = SHIPPED["hamlyn-phantom"]


def _config(predictor: str = "hold", **changes) -> RunConfig:
    return RunConfig(predictor=predictor, data=str(PHANTOM.path),
                     data_read={**PHANTOM.read, "point": 4}, sensor="recorded").replace(**changes)


def test_the_split_sets_the_settling_and_the_duration():
    c = with_split(_config(split=(100, 200)))
    assert (c.loop.settling, c.loop.duration) == (4.0, 8.0)  # samples 100 … 199 at 25 Hz
    c = with_split(_config(split=(600, 750)))  # to the end: n/f, the last frame's period
    assert (c.loop.settling, c.loop.duration) == (24.0, 30.0)
    with pytest.raises(UsageError, match="holds 750 samples"):
        with_split(_config(split=(600, 751)))
    with pytest.raises(UsageError, match="needs --data"):
        with_split(RunConfig(split=(1, 2)))
    with pytest.raises(ValueError, match="TRAIN < END"):
        RunConfig(split=(5, 5))


def test_a_recording_is_scored_at_its_measured_instants():
    """rms_error_mm is the tool against each sample of [TRAIN, END) at its instant, computed
    again here from the result's trace (which keeps the ticks at the instants) and samples;
    the all-tick score against the samples' interpolant is the second figure."""
    result, doc = run_experiment(_config(split=(150, 250)))
    assert doc["score"] == "measured" and doc["scored_samples"] == 100
    t, p, scored = result.measured
    assert scored.sum() == 100 and np.flatnonzero(scored).tolist() == list(range(150, 250))
    rows = np.searchsorted(result.time, t[scored] - 1e-9)
    np.testing.assert_allclose(result.time[rows], t[scored], atol=1e-12)
    e = np.linalg.norm(result.ee[rows] - p[scored], axis=1)
    np.testing.assert_allclose(doc["rms_error_mm"], 1e3 * np.sqrt(np.mean(e**2)), rtol=1e-12)
    np.testing.assert_allclose(doc["max_error_mm"], 1e3 * e.max(), rtol=1e-12)
    assert np.isfinite(doc["rms_error_interpolated_mm"])
    assert doc["rms_error_interpolated_mm"] != doc["rms_error_mm"]
    assert doc["settings"]["split"] == [150, 250]


def test_a_synthetic_motion_keeps_its_every_tick_score():
    _, doc = run_experiment(RunConfig(predictor="hold").replace(
        **{"loop.duration": 1.0, "loop.settling": 0.5}))
    assert doc["score"] == "continuous" and "rms_error_interpolated_mm" not in doc


def test_a_combination_scores_its_members_after_the_samples_they_learnt():
    run = build_run(_config("combination", split=(100, 150),
                            predictor_settings={"members": ["one-step", "ridge"]}))
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
