"""`rhmpc predict --data` and `rhmpc compare --data` on recordings at the rates users bring
(video 25-30 Hz, sonomicrometry 257-404 Hz), files of several points, refusals, and the shipped
PhysioNet records from outside the repository."""

from __future__ import annotations

import json
from contextlib import nullcontext
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from rhmpc.cli import main

RATES = (25.0, 30.0, 257.0, 404.0)


def heart(t: np.ndarray, seed: int = 1) -> np.ndarray:
    """(n, 3) heart 1.2 Hz + breathing 0.25 Hz [mm], 0.1 mm white noise per axis."""
    ph, b = 2 * np.pi * 1.2 * t, 2 * np.pi * 0.25 * t
    z = np.stack([1.5 * np.sin(ph) + 2 * np.sin(b), np.cos(ph) + 0.8 * np.sin(b),
                  2 * np.sin(ph + 0.5) + 1.5 * np.sin(b + 0.6)], 1)
    return z + np.random.default_rng(seed).normal(0.0, 0.1, z.shape)


def write_csv(path: Path, rate: float, seconds: float) -> Path:
    t = np.arange(0.0, seconds, 1.0 / rate)
    np.savetxt(path, np.column_stack([t, heart(t)]), delimiter=",", header="t,x,y,z",
               comments="")
    return path


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> list[Path]:
    d = tmp_path_factory.mktemp("rates")
    return [write_csv(d / f"rec{rate:g}.csv", rate, 5.0) for rate in RATES]


@pytest.mark.slow
def test_predict_data_at_every_rate(recordings: list[Path],
                                    capsys: pytest.CaptureFixture[str]) -> None:
    names = "hold,last-cycle,one-step,generalized"
    assert main(["predict", "--data", *map(str, recordings), "--predictors", names,
                 "--warmup", "2", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["rate_hz"] is None and doc["warmup_s"] == 2.0  # four rates, one warm-up
    rates = {s["label"]: s["rate_hz"] for s in doc["sources"]}
    assert rates == pytest.approx({f"rec{r:g}.csv": r for r in RATES})
    loops = {s["label"]: s["loop_lead_samples"] for s in doc["sources"]}
    assert loops == {"rec25.csv": 2, "rec30.csv": 2, "rec257.csv": 8, "rec404.csv": 12}
    for rate in RATES:
        rows = [r for r in doc["results"] if r["source"] == f"rec{rate:g}.csv"]
        leads = {1, 2, 3, 4, 5, loops[f"rec{rate:g}.csv"]}
        assert {(r["predictor"], r["lead_samples"]) for r in rows} == {
            (n, k) for n in names.split(",") for k in leads}
        for r in rows:
            assert {"predictor", "lead_samples", "lead_s", "rms_error_mm", "max_error_mm",
                    "ratio_to_hold", "rejected", "repaired"} <= set(r)
            assert r["lead_s"] == pytest.approx(r["lead_samples"] / rate)
            assert 0 < r["rms_error_mm"] <= r["max_error_mm"]
        one = next(r for r in rows if r["predictor"] == "one-step" and r["lead_samples"] == 1)
        assert one["ratio_to_hold"] < 1.0


def test_predict_data_table_and_plot(recordings: list[Path], tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    png, out = tmp_path / "leads.png", tmp_path / "leads.json"
    assert main(["predict", "--data", str(recordings[0]), "--predictors", "hold,one-step",
                 "--warmup", "2", "--leads", "3", "--plot", str(png), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "warm-up 2.0 s excluded (given)" in text
    assert "the closed loop needs lead 2 = 80 ms" in text and "⌈(40 + 0 + 25)/40⌉" in text
    assert "2/80*" in text and "one-step" in text and "max forecast error" in text
    assert png.stat().st_size > 10_000 and json.loads(out.read_text())["results"]


def test_default_warmup_is_stated(recordings: list[Path],
                                  capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["predict", "--data", str(recordings[0]), "--predictors", "hold"]) == 2
    err = capsys.readouterr().err.strip()
    assert "lasts 4.96 s; a warm-up of 10.00 s" in err and len(err.splitlines()) == 1


@pytest.mark.parametrize(("argv", "message"), [
    (["predict"], "choose --study NAME"),
    (["predict", "--study", "noise", "--data", "x.csv"], "not allowed with argument"),
    (["predict", "--study", "noise", "--points", "all"], "--points apply to --data FILE"),
    (["predict", "--data", "REC", "--trials", "3"], "--trials apply to --study"),
    (["predict", "--data", "REC", "--predictors", "exact"], "unknown predictor(s) exact"),
    (["predict", "--data", "nope.csv"], "nope.csv: no such file"),
    (["compare", "--data", "REC", "--scenarios", "fixed-a2-top"], "apply to scenarios"),
    (["compare", "--data", "REC", "--duration", "9"], "lasts 5.00 s, --duration asks for 9.00"),
    (["compare", "--rows", "0,1,2"], "need --data FILE"),
])
def test_refusals_are_one_line_exit_2(recordings: list[Path], capsys: pytest.CaptureFixture[str],
                                      argv: list[str], message: str) -> None:
    argv = [str(recordings[0]) if a == "REC" else a for a in argv]
    with pytest.raises(SystemExit) if "not allowed" in message else nullcontext():
        assert main(argv) == 2  # argparse's own refusal exits 2 as well
    err = capsys.readouterr().err.strip()
    assert message in err, err
    assert "Traceback" not in err


@pytest.mark.slow
def test_compare_data_one_row_per_predictor_and_column(recordings: list[Path],
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["compare", "--data", *map(str, recordings), "--predictors", "hold,one-step",
                 "--duration", "0.6", "--settling", "0.2", "--jobs", "1", "--json"])
    rows = json.loads(capsys.readouterr().out)["runs"]
    assert code == 0 and len(rows) == 2 * len(RATES)
    assert {(r["scenario"], r["predictor"]) for r in rows} == {
        (f"rec{rate:g}.csv", p) for rate in RATES for p in ("hold", "one-step")}
    for r in rows:
        assert {"rms_error_mm", "max_error_mm", "rms_effort_mNm"} <= set(r)
        assert r["sensor"] == "recorded" and r["data"].endswith(r["scenario"])
        assert np.isfinite(r["rms_error_mm"])


def test_compare_data_table(recordings: list[Path], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["compare", "--data", str(recordings[0]), "--predictors", "hold,one-step",
                 "--duration", "0.6", "--settling", "0.2", "--jobs", "1"]) == 0
    out = capsys.readouterr().out
    assert "rec25.csv" in out and "ratio to hold" in out and "one-step" in out


def test_several_points_predict_and_compare(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """A 12 × N MAT file of four 3-D points (video tracking): each point, and their mean."""
    t = np.arange(0.0, 5.0, 1 / 25.0)
    X = np.vstack([heart(t, seed=k).T for k in range(4)])  # x1, y1, z1, x2, …
    path = tmp_path / "points.mat"
    scipy.io.savemat(path, {"X": X, "units": "mm"})
    argv = ["predict", "--data", str(path), "--rate", "25", "--predictors", "hold,one-step",
            "--warmup", "2", "--leads", "2"]
    assert main(argv) == 2
    assert "holds 4 tracked points" in capsys.readouterr().err
    assert main([*argv, "--points", "all", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    labels = list(dict.fromkeys(r["source"] for r in doc["results"]))
    assert labels == ["points.mat:p1", "points.mat:p2", "points.mat:p3", "points.mat:p4",
                      "points.mat:mean"]
    by = {(r["source"], r["predictor"], r["lead_samples"]): r["rms_error_mm"]
          for r in doc["results"]}
    assert by["points.mat:mean", "one-step", 1] == pytest.approx(
        np.mean([by[f"points.mat:p{k}", "one-step", 1] for k in range(1, 5)]))
    assert main(["compare", "--data", str(path), "--rate", "25", "--points", "2,4",
                 "--predictors", "hold", "--duration", "0.6", "--settling", "0.2",
                 "--jobs", "1", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)["runs"]
    assert [(r["scenario"], r["point"]) for r in rows] == [("points.mat:p2", 2),
                                                          ("points.mat:p4", 4)]
    assert rows[0]["settings"]["data_read"] == {"rate": 25.0, "point": 2}


def test_rr_mitdb_100_from_outside_the_repository(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "--rr", "mitdb-100", "--duration", "0.5", "--settling", "0.1",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["scenario"].endswith("+rr:mitdb-100") and np.isfinite(doc["rms_error_mm"])
    assert main(["predict", "--study", "rr", "--records", "1003", "--trials", "1",
                 "--predictors", "last-cycle", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["rows"]


@pytest.fixture(scope="module")
def surface(tmp_path_factory) -> Path:
    """A 12 × 400 MAT file (mm, 25 frames/s) of four points of one surface."""
    from tests.predictors.helpers import tracked_points

    pts = 1e3 * tracked_points(400, 0.04, seed=2, noise=20e-6)  # (T, 4, 3) [mm]
    path = tmp_path_factory.mktemp("surface") / "surface.mat"
    scipy.io.savemat(path, {"measures": pts.reshape(400, 12).T})
    return path


@pytest.mark.slow
def test_predict_the_literatures_protocol(surface: Path, tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "leads.png"
    argv = ["predict", "--data", str(surface), "--poi", "4", "--split", "250:350", "--leads",
            "4", "--rate", "25", "--units", "mm", "--predictors",
            "hold,one-step,st-rls,st-ridge,combination"]
    assert main([*argv, "--json", "--plot", str(png)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert png.stat().st_size > 0 and doc["protocol"] == "split"
    fam = {r["predictor"]: r["family"] for r in doc["results"]}
    assert fam == {"hold": "baseline", "one-step": "adaptive", "st-rls": "multi-point",
                   "st-ridge": "learned", "combination": "combination"}
    assert {r["source"] for r in doc["results"]} == {"surface.mat:p4"}
    assert all(r["scored"] == 100 for r in doc["results"])
    assert main([*argv, "--train", str(surface)]) == 0
    out = capsys.readouterr().out
    assert "fitted on the training recordings" in out and "multi-point" in out


@pytest.mark.parametrize(("extra", "message"), [
    (["--poi", "4", "--points", "all"], "choose one"),
    (["--poi", "0"], "numbered from 1"),
    (["--poi", "5"], "no point 5"),
    (["--poi", "4", "--split", "600"], "expected TRAIN:END"),
    (["--poi", "4", "--split", "300:200"], "0 < TRAIN < END"),
    (["--poi", "4", "--split", "500:600"], "the split starts scoring at sample 500"),
    (["--poi", "4", "--split", "250:350", "--warmup", "2"], "takes no warm-up"),
    (["--poi", "4", "--predictors", "st-ridge", "--warmup", "2"], "fitted before the run"),
    (["--poi", "4", "--split", "250:350", "--train", "nope.mat"], "nope.mat: no such file"),
])
def test_protocol_refusals_are_one_line_exit_2(surface: Path, capsys: pytest.CaptureFixture[str],
                                               extra: list[str], message: str) -> None:
    argv = ["predict", "--data", str(surface), "--rate", "25", "--units", "mm", *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1 and "Traceback" not in err, err
