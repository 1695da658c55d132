"""`rhmpc predict` and the prediction studies (small, seeded runs)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rhmpc.cli import main
from rhmpc.openloop.studies import StudySettings, default_records, run_study
from rhmpc.openloop.studies_report import format_table


def _rows(result):
    return {(r["parameter"], r["predictor"]): r for r in result["rows"]}


@pytest.mark.slow
def test_noise_study_reproduces_yuen_ordering():
    s = StudySettings(
        "noise",
        trials=3,
        seed=1,
        noise_mm=(1.3,),
        predictors=("ekf", "ar", "fading-ar", "last-cycle"),
    )
    rows = _rows(run_study(s))
    ekf, ar, far, lc = (rows[1.3, n]["rms_mm"] for n in ("ekf", "ar", "fading-ar", "last-cycle"))
    assert ekf < ar < far < 1.3  # Yuen Fig. 3A: all three below σ_R, EKF best, AR < fading AR
    assert lc == pytest.approx(1.3, rel=0.15)  # last cycle ≈ σ_R


def test_hr_step_fading_ar_beats_ar_for_large_steps():
    s = StudySettings(
        "hr-step", trials=2, seed=2, delta_bpm=(10.0,), predictors=("ekf", "ar", "fading-ar")
    )
    rows = _rows(run_study(s))
    assert rows[10.0, "fading-ar"]["rms_mm"] < rows[10.0, "ar"]["rms_mm"]
    assert rows[10.0, "ekf"]["rms_mm"] < 1.3


def test_studies_are_reproducible_and_parallel_equals_serial():
    s = StudySettings("noise", trials=2, seed=3, noise_mm=(0.6,), predictors=("ar", "last-cycle"))
    a, b = run_study(s), run_study(s, jobs=2)
    assert [r["rms_mm"] for r in a["rows"]] == [r["rms_mm"] for r in b["rows"]]


@pytest.mark.slow
def test_horizon_study_error_grows_with_lead_and_exact_is_zero():
    s = StudySettings(
        "horizon",
        trials=1,
        seed=4,
        scenarios=("fixed-a2-top",),
        predictors=("generalized", "hold", "exact"),
    )
    result = run_study(s)
    rows = _rows(result)
    hold = np.array(rows["fixed-a2-top", "hold"]["rms_mm"])
    assert np.all(np.diff(hold) > 0)
    assert max(rows["fixed-a2-top", "exact"]["rms_mm"]) < 1e-9
    assert rows["fixed-a2-top", "generalized"]["rms_mm"][3] < hold[3]
    assert "lead [ms]" in format_table(result)


def test_rr_study_runs_on_a_physionet_record():
    s = StudySettings(
        "rr",
        trials=1,
        seed=5,
        records=("1003",),
        predictors=("ekf", "last-cycle"),
    )
    rows = _rows(run_study(s))
    assert all(np.isfinite(r["rms_mm"]) for r in rows.values())
    assert default_records() == ("1003", "mitdb-100")


def test_cli_predict_writes_json_table_and_plot(tmp_path, capsys):
    out, png = tmp_path / "r.json", tmp_path / "r.png"
    code = main(
        [
            "predict",
            "--study",
            "noise",
            "--trials",
            "1",
            "--noise-mm",
            "0.3,3",
            "--predictors",
            "ar,last-cycle",
            "--seed",
            "7",
            "--out",
            str(out),
            "--plot",
            str(png),
        ]
    )
    assert code == 0
    table = capsys.readouterr().out
    assert "last-cycle" in table and "σ_R" in table
    data = json.loads(out.read_text())
    assert data["study"] == "noise" and len(data["rows"]) == 4
    assert png.stat().st_size > 0
    assert (
        main(
            [
                "predict",
                "--study",
                "noise",
                "--trials",
                "1",
                "--noise-mm",
                "1",
                "--predictors",
                "hold",
                "--json",
            ]
        )
        == 0
    )
    assert json.loads(capsys.readouterr().out)["rows"][0]["predictor"] == "hold"


@pytest.mark.parametrize(
    "argv",
    [
        ["predict", "--study", "noise", "--predictors", "kalman"],
        ["predict", "--study", "noise", "--trials", "0"],
        ["predict", "--study", "noise", "--noise-mm", "a,b"],
        ["predict", "--study", "noise", "--predictors", "exact"],
        ["predict", "--study", "rr", "--records", "/nonexistent/rec"],
        ["predict", "--study", "horizon", "--scenarios", "nope"],
    ],
)
def test_cli_predict_rejects_bad_input(argv, capsys):
    assert main(argv) == 2
    assert "error" in capsys.readouterr().err


def test_hr_step_protocols_and_synchronised_last_cycle():
    """Yuen (60 bpm) stays the default; tuna2013 runs at 103 bpm.  Last cycle synchronised on
    the beat times: measured 1.7/2.7 mm at ΔHR = ∓10 with them, 4.0–4.5 mm without."""
    with pytest.raises(ValueError, match="paper"):
        StudySettings("hr-step", paper="nope")
    assert StudySettings("hr-step").paper == "yuen2008"
    s = StudySettings(
        "hr-step",
        trials=1,
        seed=2,
        delta_bpm=(-10.0,),
        predictors=("last-cycle",),
        paper="tuna2013",
    )
    result = run_study(s)
    assert result["settings"]["paper"] == "tuna2013"
    assert _rows(result)[-10.0, "last-cycle"]["rms_mm"] < 3.0


def test_28hz_rls_predictors_run_at_order_30():
    from rhmpc.openloop.studies import ORDER_28HZ, _yuen_predictor

    beats = np.arange(0.0, 50.0)
    for name in ("one-step", "generalized"):
        assert _yuen_predictor(name, 1 / 28, 1.3e-3, False, beats, 0.0).settings.order == 30
    lc = _yuen_predictor("last-cycle", 1 / 28, 1.3e-3, False, beats, 0.0)
    assert lc.settings.beat_times == tuple(beats) and ORDER_28HZ == 30


@pytest.mark.slow
def test_horizon_study_reports_heart_rate_error():
    s = StudySettings(
        "horizon", trials=1, seed=4, scenarios=("fixed-a2-top",), predictors=("ekf", "hold")
    )
    result = run_study(s)
    rows = _rows(result)
    assert rows["fixed-a2-top", "ekf"]["hr_err_bpm_rms"] < 5.0  # measured 1.1 bpm
    assert "hr_err_bpm_rms" not in rows["fixed-a2-top", "hold"]
    assert "|ω̂ − ω|" in format_table(result)


def test_cli_predict_rejects_an_unknown_paper(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["predict", "--study", "hr-step", "--paper", "nope"])
    assert exc.value.code == 2
