"""Predictors that learn before the run, and the other tracked points, in a closed-loop run:
fitted on the settling window only (nothing scored is in their training), the other points of a
recording given with each sample, the shipped recording by name."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rhmpc.cli import main
from rhmpc.experiment import RunConfig
from rhmpc.experiment.assembly import build_run
from rhmpc.experiment.fitting import settling_series
from rhmpc.sim.recordings.shipped import SHIPPED, resolve

PHANTOM = SHIPPED["hamlyn-phantom"]


def _config(predictor: str, duration: float = 12.0, settling: float = 6.0,
            path: str | None = None) -> RunConfig:
    return RunConfig(predictor=predictor, data=path or str(PHANTOM.path),
                     data_read={**PHANTOM.read, "point": 4}, sensor="recorded").replace(
        **{"loop.duration": duration, "loop.settling": settling})


def test_the_shipped_recording_resolves_by_name_and_a_file_wins(tmp_path, monkeypatch):
    path, read, poi = resolve("hamlyn-phantom", {"units": "mm"})
    assert path == str(PHANTOM.path) and read == PHANTOM.read and poi == 4
    monkeypatch.chdir(tmp_path)
    (tmp_path / "hamlyn-phantom").write_text("t,x\n0,1\n")
    assert resolve("hamlyn-phantom", {}) == ("hamlyn-phantom", {}, None)


def test_the_settling_series_is_what_the_predictor_reads_before_the_score():
    run = build_run(_config("st-rls"))
    series = settling_series(run)
    assert series.shape == (150, 4, 3)  # 6 s at 25 frames/s, the POI and the 3 others
    from rhmpc.sim.recordings import load_points

    points = load_points(PHANTOM.path, **PHANTOM.read)
    z = np.stack([p.z for p in points], axis=1)[:150]  # (T, 4, 3), point 4 is the POI
    rows = np.concatenate([z[:, 3:4], z[:, :3]], axis=1)  # as measured: the sensor's frame
    np.testing.assert_allclose(series, rows, atol=1e-12)


@pytest.mark.slow
def test_a_fitted_predictor_learns_only_before_the_scored_part(tmp_path):
    """The recording changed after the settling window leaves the fitted model unchanged: the
    predictor reads the samples as measured, whatever the run's mean, where the motion is
    placed."""
    from scipy.io import loadmat, savemat

    data = loadmat(PHANTOM.path)["measures"].copy()
    data[:, 200:] += np.random.default_rng(0).normal(0.0, 1.0, data[:, 200:].shape)
    other = tmp_path / "changed.mat"
    savemat(other, {"measures": data})
    models = []
    for path in (str(PHANTOM.path), str(other)):
        predictor = build_run(_config("st-ridge", path=path)).reference.predictor
        assert predictor.fitted
        models.append(predictor.model["W"])
    for a, b in zip(*models, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)


@pytest.mark.slow
def test_a_multi_point_predictor_reads_the_other_points_in_closed_loop(capsys):
    assert main(["simulate", "--data", "hamlyn-phantom", "--predictor", "st-rls",
                 "--duration", "12", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["settings"]["data_read"]["point"] == 4  # the shipped file's POI
    assert "others_missing" not in doc["predictor_counts"]
    assert np.isfinite(doc["rms_error_mm"]) and doc["rms_error_mm"] < 0.5


def test_train_files_and_poi_need_data(capsys):
    assert main(["simulate", "--poi", "2", "--duration", "1"]) == 2
    assert "--poi and --split need --data" in capsys.readouterr().err
    assert main(["simulate", "--data", "hamlyn-phantom", "--train", "nosuch.csv",
                 "--duration", "1"]) == 2
    assert "--train: no such file nosuch.csv" in capsys.readouterr().err


def test_a_run_says_what_it_fits_and_about_how_long_before_it_fits():
    """The members fitted before the run, and only they, named with their estimate."""
    pytest.importorskip("torch")
    from rhmpc.experiment.fitting import announcement
    from rhmpc.predictors import make_predictor

    combination = make_predictor("combination", 0.04, members=("one-step", "st-ridge", "tcn"))
    t = np.arange(300) * 0.04
    series = [np.sin(2 * np.pi * 1.2 * t)[:, None, None] * np.ones((1, 1, 3)) * 1e-3]
    lines = announcement("combination", combination, series, seed=0)
    assert lines[0] == "fitting st-ridge, tcn on 300 samples (1 series) before the run"
    assert "validation round on the first 80 % of those frames (0–239)" in lines[1]
    assert lines[2].startswith("about ") and "st-ridge about a second" in lines[2]
    assert "tcn " in lines[2] and "networks × 2 rounds" in lines[2]
