"""Recordings on the command line: MATLAB flags, default duration, refusals (one line, exit 2)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from rhmpc.cli import main
from rhmpc.cli.simulate import config_from_args, register

T = np.arange(0, 20, 0.01)
X = np.vstack([4 * np.sin(2 * np.pi * 1.3 * T), 2 * np.sin(2 * np.pi * 2.6 * T),
               3 * np.cos(2 * np.pi * 1.3 * T)])


def _args(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    return parser.parse_args(["simulate", *argv])


def test_default_duration_is_the_recording(tmp_path: Path) -> None:
    path = tmp_path / "rec.mat"
    scipy.io.savemat(path, {"X": X})
    config = config_from_args(_args("--data", str(path), "--var", "X", "--rate", "100",
                                    "--units", "mm"))
    assert config.loop.duration == pytest.approx(20.0)  # 2000 samples at 100 Hz
    assert config.data_read == {"var": "X", "rate": 100.0, "units": "mm"}
    csv = tmp_path / "rec.csv"
    t = np.arange(0, 20, 1 / 400)  # 8000 samples at 400 Hz: 20 s
    csv.write_text("t,x,y,z\n" + "".join(f"{ti:.4f},1,2,3\n" for ti in t))
    assert config_from_args(_args("--data", str(csv))).loop.duration == pytest.approx(20.0)


def test_too_long_request_names_both_lengths(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    csv = tmp_path / "rec.csv"
    t = np.arange(0, 20, 1 / 400)
    x = 3.0 * np.sin(2 * np.pi * 1.2 * t)  # a heart-like 6 mm [mm]: no word on its amplitude
    rows = (f"{ti:.4f},{xi:.4f},2,3\n" for ti, xi in zip(t, x, strict=True))
    csv.write_text("t,x,y,z\n" + "".join(rows))
    assert main(["simulate", "--data", str(csv), "--duration", "20.001"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "lasts 20.000 s" in err and "asks for 20.001 s" in err  # digits enough to differ


@pytest.mark.parametrize(("variables", "flags", "message"), [
    ({"Y": X}, ["--var", "X", "--rate", "100"], "no numeric variable 'X'"),
    ({"X": np.zeros((3, 3))}, ["--var", "X", "--rate", "100"], "ambiguous"),
    ({"X": X, "t": T[::-1]}, ["--var", "X"], "does not increase"),
    ({"X": np.full((3, 40), np.nan)}, ["--var", "X", "--rate", "100"], "all NaN"),
])
def test_simulate_refuses_bad_mat(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                  variables: dict, flags: list, message: str) -> None:
    path = tmp_path / "bad.mat"
    scipy.io.savemat(path, variables)
    assert main(["simulate", "--data", str(path), *flags]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_data_show_and_export_a_mat_file(tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "rec.mat"
    scipy.io.savemat(path, {"M": X.T * 1e-3, "units": "m"})
    assert main(["data", "show", str(path), "--cols", "0,1,2", "--rate", "100", "--json"]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["dim"] == 3 and row["sensor_rate_hz"] == pytest.approx(100.0)
    assert row["peak_to_peak_mm"] == pytest.approx(8.0, rel=0.01)
    assert 0 <= row["predictability"] < 0.2  # two sines: a line spectrum
    out = tmp_path / "rec.csv"
    assert main(["data", "export", str(path), str(out), "--rate", "100"]) == 0
    assert "wrote 2000 samples" in capsys.readouterr().out
    assert main(["simulate", "--var", "X"]) == 2
    assert "--data" in capsys.readouterr().err


def _recording(path: Path, rate: float, seconds: float, noise_mm: float = 0.1,
               seed: int = 1) -> Path:
    """A 3-D heart-like recording (1.2 Hz heart, 0.25 Hz breathing, white noise) as CSV."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / rate)
    phase = 2 * np.pi * 1.2 * t
    z = np.column_stack([1.5 * np.sin(phase) + 0.5 * np.sin(2 * phase + 0.4),
                         np.cos(phase) + 0.3 * np.sin(2 * phase),
                         2 * np.sin(phase + 0.5) + 0.25 * np.sin(4 * phase)])
    z += np.outer(np.sin(2 * np.pi * 0.25 * t), [2.0, 0.8, 1.5])
    z += rng.normal(0.0, noise_mm, z.shape)
    np.savetxt(path, np.column_stack([t, z]), delimiter=",", header="t,x,y,z", comments="")
    return path


@pytest.mark.parametrize(("rate", "mode"), [(25.0, "sensor"), (30.0, "sensor"),
                                            (257.0, "downsample"), (404.0, "downsample")])
@pytest.mark.slow
def test_a_recording_at_any_rate_runs_with_the_right_predictor_clock(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], rate: float, mode: str) -> None:
    path = _recording(tmp_path / "rec.csv", rate, 4.0)
    assert main(["simulate", "--data", str(path), "--predictor", "one-step", "--settling", "2",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    clock = doc["predictor_clock"]
    assert clock["mode"] == mode
    assert clock["sensor_rate_hz"] == pytest.approx(rate, rel=1e-6)
    assert clock["dt_s"] == pytest.approx(1 / rate if mode == "sensor" else 7.5e-3)
    assert np.isfinite(doc["rms_error_mm"]) and doc["fallbacks"] == 0


@pytest.mark.slow
def test_a_clean_recording_gets_no_rejections_and_the_summary_says_why(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Regularly spaced samples with Gaussian noise: the gate, calibrated on this recording's
    own one-step miss, rejects nothing; the summary states the regime, the floor and the
    settling rule."""
    path = _recording(tmp_path / "rec.csv", 25.0, 24.0)
    assert main(["simulate", "--data", str(path), "--predictor", "generalized"]) == 0
    out = capsys.readouterr().out
    assert "predictor on raw samples at 25 Hz" in out
    assert "floor" in out and "rejected 0," in out
    assert "settling by default 10 s, or a third of a run shorter than 30 s" in out


def test_a_run_too_short_to_score_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--duration", "0.01"]) == 2
    err = capsys.readouterr().err
    assert "scored on" in err and len(err.strip().splitlines()) == 1
