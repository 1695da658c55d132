"""`rhmpc simulate` and `rhmpc compare` from the command line (short runs)."""

import json

import numpy as np
import pytest

from rhmpc.cli import main
from rhmpc.experiment import RunConfig, load_config, save_config

FAST = ["--duration", "1.0", "--settling", "0.3"]


def run_cli(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.slow
def test_simulate_json_document(capsys, tmp_path):
    out_file = tmp_path / "run.json"
    code, out, _ = run_cli(capsys, "simulate", "--predictor", "one-step", *FAST, "--json",
                           "--out", str(out_file), "--seed", "2")
    assert code == 0
    doc = json.loads(out)
    assert doc == json.loads(out_file.read_text())
    assert doc["predictor"] == "one-step" and doc["seed"] == 2 and doc["robot"] == "phantom"
    assert doc["scenario"] == "fixed-a2-top"
    assert set(doc["tick_us"]) >= {"p50", "p99", "max"}
    assert np.isfinite(doc["rms_error_mm"]) and doc["rms_error_mm"] > 0
    # the predictor's running RMS miss per lead, the input of benchmarks/horizon_weights.py
    errors = [e for e in doc["forecast_error_rms_mm"] if e is not None]
    assert len(errors) >= 4 and 0 < errors[0] < errors[-1] < 5
    assert doc["forecast_lead_s"] == pytest.approx(15 * 0.0005)


@pytest.mark.slow
def test_simulate_summary_and_plot(capsys, tmp_path):
    png = tmp_path / "fig.png"
    code, out, _ = run_cli(capsys, "simulate", "--predictor", "exact", *FAST, "--plot", str(png),
                           "--host-stalls", "0.05")
    assert code == 0
    assert "tracking error" in out and "controller tick" in out
    assert "a busy loop of 0.05 s stalled" in out  # the host's stalls beside the tick
    assert png.stat().st_size > 10_000


@pytest.mark.slow
def test_simulate_reports_the_host_stalls_in_gain_ticks(capsys):
    code, out, _ = run_cli(capsys, "simulate", "--predictor", "exact", *FAST, "--json",
                           "--host-stalls", "0.05")
    assert code == 0
    doc = json.loads(out)
    stalls = doc["host_stalls"]
    assert stalls["seconds"] == 0.05 and stalls["floor_us"] == 20.0
    assert 0 <= stalls["over_50_g"] <= stalls["stalls"]
    g = doc["gain_tick_us"]["p50"]
    assert stalls["longest_g"] == pytest.approx(stalls["longest_us"] / g)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--predictor", "oracle9"], "unknown predictor 'oracle9'"),
        (["--robot", "puma"], "unknown robot 'puma'"),
        (["--scenario", "nope"], "unknown scenario 'nope'"),
        (["--data", "/no/such/file.csv"], "no such file"),
        (["--set", "mpc.effort_weight=-1"], "effort_weight"),
        (["--set", "mpc.nonsense=1"], "nonsense"),
        (["--set", "loop"], "SECTION.KEY=VALUE"),
        (["--duration", "0"], "duration"),
        (["--host-stalls", "-1"], "--host-stalls"),
    ],
)
def test_bad_options_give_one_line_error_and_exit_2(capsys, argv, message):
    code, _, err = run_cli(capsys, "simulate", *argv)
    assert code == 2
    lines = [line for line in err.splitlines() if "error" in line]
    assert len(lines) == 1 and message in lines[0], err


@pytest.mark.slow
def test_config_file_round_trip_and_precedence(capsys, tmp_path):
    cfg = RunConfig(predictor="hold", seed=5).replace(**{"loop.duration": 1.0,
                                                        "loop.settling": 0.2,
                                                        "mpc.effort_weight": 2e-4})
    path = tmp_path / "run.toml"
    save_config(cfg, path)
    assert load_config(path) == cfg
    code, out, _ = run_cli(capsys, "simulate", "--config", str(path), "--json", "--seed", "6")
    doc = json.loads(out)
    assert code == 0 and doc["predictor"] == "hold" and doc["seed"] == 6
    assert doc["settings"]["mpc"]["effort_weight"] == 2e-4
    bad = tmp_path / "bad.toml"
    bad.write_text("predictor = 'hold'\n[mpc]\nwrong_key = 1\n")
    code, _, err = run_cli(capsys, "simulate", "--config", str(bad))
    assert code == 2 and "wrong_key" in err and str(bad) in err


def test_simulate_a_recording(capsys, tmp_path):
    t = np.arange(0, 2.0, 1 / 257)
    x = 4 * np.sin(2 * np.pi * 1.66 * t)
    lines = ["t,x,y,z"] + [f"{a:.6f},{b:.4f},{0.5 * b:.4f},0" for a, b in zip(t, x, strict=True)]
    path = tmp_path / "heart.csv"
    path.write_text("\n".join(lines) + "\n")
    code, out, err = run_cli(capsys, "simulate", "--data", str(path), "--predictor", "generalized",
                             *FAST, "--json")
    assert code == 0, err
    doc = json.loads(out)
    assert doc["scenario"] == "file:heart.csv" and doc["sensor"] == "recorded"
    code, _, err = run_cli(capsys, "simulate", "--data", str(path), "--duration", "5")
    assert code == 2 and "recording lasts" in err


@pytest.mark.slow
def test_compare_prints_the_table(capsys):
    code, out, _ = run_cli(capsys, "compare", "--predictors", "exact,hold", "--scenarios",
                           "fixed-a2-top", "--duration", "0.8", "--settling", "0.2", "--jobs", "2")
    assert code == 0
    assert "RMS position error" in out and "ratio to exact" in out
    assert "hold" in out and "fixed-a2-top" in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--predictors", "exact,foo"], "unknown predictor(s) foo"),
        (["--scenarios", "nope"], "unknown scenario(s) nope"),
        (["--seeds", "0"], "--seeds"),
    ],
)
def test_compare_bad_options_exit_2_before_running(capsys, argv, message):
    code, _, err = run_cli(capsys, "compare", *argv)
    assert code == 2 and message in err, err


def test_the_summary_says_where_the_motion_is_and_what_ran(capsys):
    """The summary states the motion's placement (re-centred on its mean unless set absolute),
    the speed against real time and, with ``--controller c``, that the library's own RLS
    predictor served the refreshes."""
    from rhmpc.report.summary import format_summary

    code, out, _ = run_cli(capsys, "simulate", "--predictor", "generalized", *FAST, "--json")
    assert code == 0
    doc = json.loads(out)
    text = format_summary(doc)
    assert "centred on its mean" in text and 'loop.placement = "absolute"' in text
    assert "than real time" in text and "own RLS" not in text
    absolute = {**doc, "settings": {**doc["settings"], "loop": {
        **doc["settings"]["loop"], "placement": "absolute"}}}
    assert "own coordinates" in format_summary(absolute)
    assert "its own RLS predictor" in format_summary({**doc, "implementation": "c"})
