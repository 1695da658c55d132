"""`rhmpc compare`: progress before the runs end, failed cells, tables within 120 characters,
recordings against `hold`, intervals over seeds, CSV.

Most tests stand in for the closed-loop run (:func:`rhmpc.compare.jobs.run_job`) with a function
whose metrics follow from the predictor, the column and the seed, so that they run in a
fraction of a second; the workers are forked, so they see the stand-in.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from rhmpc.cli import compare, main
from rhmpc.compare import jobs as compare_jobs
from rhmpc.compare.table import MAX_WIDTH, comparison_table, grid, interval95
from rhmpc.experiment.run import jsonable
from rhmpc.paper.tables import COLUMNS, paper_table

REPO = Path(__file__).resolve().parents[3]

#: How the stand-in behaves (set by a test before the workers fork).
STAND_IN: dict = {"delay": 0.0, "fail": set(), "crash": set(), "settings": True}
BASE_MM = {"exact": 0.2, "hold": 0.4, "one-step": 0.22, "generalized": 0.21, "ekf": 0.6}


def stand_in(job: compare_jobs.Job) -> dict:
    """Metrics from the predictor, the column and the seed, after ``delay`` seconds; fails for
    (predictor, column) in ``fail``, kills its worker for those in ``crash``."""
    time.sleep(STAND_IN["delay"])
    config = job.config
    if (config.predictor, job.column) in STAND_IN["crash"]:
        os._exit(3)
    if (config.predictor, job.column) in STAND_IN["fail"]:
        doc = compare_jobs.failed_doc(job, "RuntimeError: boom")
        if not STAND_IN["settings"]:
            doc.pop("settings")
        return compare_jobs.labelled(doc, job)
    rms = BASE_MM[config.predictor] * (1 + 0.1 * config.seed) * (1 + 0.01 * len(job.column))
    doc = {"predictor": config.predictor, "seed": config.seed, "rms_error_mm": rms,
           "max_error_mm": 3 * rms, "rms_effort_mNm": 100 * rms, "wall_s": 0.1,
           "prediction_rms_mm": {"lead_N": rms}, "ended": time.time(),
           "settings": jsonable(config.to_dict())}
    return compare_jobs.labelled(doc, job)


@pytest.fixture
def standin(monkeypatch: pytest.MonkeyPatch) -> dict:
    """The stand-in in place of the closed-loop run; its settings to change."""
    monkeypatch.setattr(compare_jobs, "run_job", stand_in)
    monkeypatch.setitem(STAND_IN, "delay", 0.0)
    monkeypatch.setitem(STAND_IN, "fail", set())
    monkeypatch.setitem(STAND_IN, "crash", set())
    monkeypatch.setitem(STAND_IN, "settings", True)
    return STAND_IN


class Recorder(io.StringIO):
    """A stream that notes when it was first written to."""

    def __init__(self) -> None:
        super().__init__()
        self.first: float | None = None

    def write(self, text: str) -> int:
        if self.first is None and text.strip():
            self.first = time.time()
        return super().write(text)

    def isatty(self) -> bool:
        return False


@pytest.mark.slow
def test_header_and_progress_come_before_the_first_run_ends(
        standin: dict, monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    standin["delay"] = 0.8
    out, err = Recorder(), Recorder()
    monkeypatch.setattr(sys, "stdout", out)
    monkeypatch.setattr(sys, "stderr", err)
    start = time.time()
    code = main(["compare", "--scenarios", "fixed-a2-top,fixed-a1-top", "--predictors",
                 "hold,one-step", "--duration", "8", "--jobs", "2", "--out",
                 str(tmp_path / "runs.json")])
    assert code == 0
    first_end = min(d["ended"]
                    for d in json.loads((tmp_path / "runs.json").read_text())["runs"])
    assert err.first is not None and err.first - start < 0.5
    assert err.first < first_end - 0.4  # while the first runs are in flight
    assert out.first is not None and out.first < first_end
    assert out.getvalue().startswith("rhmpc compare: 4 runs (2 predictors × 2 scenarios × 1 "
                                     "seed)")
    text = err.getvalue()
    assert text.startswith("rhmpc compare: timing a 2-s run of hold on fixed-a2-top")
    assert "rhmpc compare: running 4 run(s) on 2 local process(es)" in text
    assert "4/4 runs |" in text  # the bar
    assert "each run 80× faster than real time" in text  # 8 s simulated in 0.1 s
    assert "8 s each (metrics after 2.7 s)" in out.getvalue()


def test_quiet_silences_progress(standin: dict, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["compare", "--scenarios", "fixed-a2-top", "--predictors", "hold,exact",
                 "--duration", "1", "--jobs", "1", "--quiet"]) == 0
    captured = capsys.readouterr()
    assert captured.err == "" and "ratio to exact" in captured.out


def test_failed_cells_read_failed_and_hardware_runs_stay_beside_table_2(
        standin: dict, capsys: pytest.CaptureFixture[str]) -> None:
    standin["fail"] = {("one-step", "fixed-a1-top")}
    code = main(["compare", "--preset", "tuna2013-hardware", "--paper", "--scenarios",
                 "fixed-a1-top,fixed-a2-top", "--predictors", "exact,one-step,generalized",
                 "--duration", "1", "--jobs", "2"])
    captured = capsys.readouterr()
    assert code == 1
    assert "failed: one-step on fixed-a1-top seed 0: RuntimeError: boom" in captured.err
    table, paper = captured.out.split("Our runs:")
    assert _row(table, "one-step").split()[1] == "failed"
    assert "Table II (hardware experiments)" in paper and "Table I (simulation)" not in paper
    assert "0.404 / failed" in paper  # Table II(a), fixed-a1-top, one-step RMS
    assert "set beside Tables II–III (hardware) only" in paper


def test_paper_table_keeps_its_setting_when_failed_runs_have_no_settings() -> None:
    docs = [{"predictor": p, "scenario": s, "seed": 0, "rms_error_mm": 0.2,
             "max_error_mm": 1.0, "rms_effort_mNm": 30.0, "prediction_rms_mm": {"lead_N": 0.2},
             "settings": {"plant": {"delay_ticks": 1}}}
            for p in ("exact", "generalized") for s in COLUMNS]
    docs += [{"predictor": "one-step", "scenario": s, "seed": 0, "error": "boom"}
             for s in COLUMNS]
    preds = ["exact", "one-step", "generalized"]
    for setting in (None, "hardware"):
        text = paper_table(docs, preds, list(COLUMNS), setting=setting)
        assert "Table II (hardware" in text and "Table I (simulation)" not in text
        assert text.count("/ failed") == 3 * len(COLUMNS)  # RMS, max and effort tables


def test_a_worker_that_dies_is_a_failed_run(standin: dict,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    standin["crash"] = {("one-step", "fixed-a2-top")}
    code = main(["compare", "--scenarios", "fixed-a2-top", "--predictors", "hold,one-step",
                 "--duration", "1", "--jobs", "1"])
    captured = capsys.readouterr()
    assert code == 1 and "worker died" in captured.err and "Traceback" not in captured.err
    assert "failed" in _row(captured.out, "one-step")


def _row(text: str, label: str) -> str:
    return next(line for line in text.splitlines() if line.startswith(label + " "))


def _docs(columns: list[str], predictors: list[str], seeds: int = 1) -> list[dict]:
    return [{"predictor": p, "scenario": c, "seed": s, "rms_error_mm": BASE_MM[p] * (1 + s),
             "max_error_mm": 1.234, "rms_effort_mNm": 123.45}
            for c in columns for p in predictors for s in range(seeds)]


@pytest.mark.parametrize("seeds", [1, 10])
def test_many_columns_are_transposed_within_120_characters(seeds: int) -> None:
    columns = [f"recording_of_animal_{k}_2023.mat:p{k}" for k in range(1, 9)]
    preds = ["hold", "exact", "one-step", "generalized", "ekf"]
    text = comparison_table(_docs(columns, preds, seeds), preds, columns, recordings=True)
    assert max(map(len, text.splitlines())) <= MAX_WIDTH
    for col in columns:  # one row per column
        assert sum(line.startswith(col + " ") for line in text.splitlines()) == 3 + (seeds > 1)
    assert "ratio to hold" in text


def test_too_wide_both_ways_is_split_into_blocks() -> None:
    rows = [f"row-{k:02d}" for k in range(30)]
    cols = [f"column-{k:02d}" for k in range(30)]
    lines = grid("title", rows, cols, lambda r, c: "1.234 ± 0.567")
    assert max(map(len, lines)) <= MAX_WIDTH
    cells = sum(line.count("1.234 ± 0.567") for line in lines)
    assert cells == 30 * 30


def test_paper_tables_fit_in_120_characters() -> None:
    preds = ["exact", "one-step", "generalized", "ekf"]
    docs = [{**d, "settings": {"plant": {"model": "linear"}}}
            for d in _docs(list(COLUMNS), preds, seeds=10)]
    text = paper_table(docs, preds, list(COLUMNS)).split("Published findings")[0]
    assert max(map(len, text.splitlines())) <= MAX_WIDTH
    assert "the mean ± the half-width of its 95 % interval over 10 runs (seeds 0–9)" in text


def test_interval_is_students_t() -> None:
    mean, half = interval95([1.0, 2.0, 3.0])
    assert mean == 2.0 and half == pytest.approx(4.302652729911275 / math.sqrt(3))
    assert math.isnan(interval95([1.0])[1]) and math.isnan(interval95([])[0])


def test_seeds_give_a_mean_and_interval_per_cell(
        standin: dict, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["compare", "--scenarios", "fixed-a2-top", "--predictors", "exact,one-step",
            "--duration", "1", "--jobs", "2", "--seeds", "3", "--seed", "5"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "over 3 runs (seeds 5–7)" in out and "±" in out
    assert main([*argv, "--csv"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert [(r["column"], r["predictor"], r["runs"]) for r in rows] == [
        ("fixed-a2-top", "exact", "3"), ("fixed-a2-top", "one-step", "3")]
    values = [BASE_MM["one-step"] * (1 + 0.1 * s) * 1.12 for s in (5, 6, 7)]
    mean, half = interval95(values)
    assert float(rows[1]["rms_error_mm"]) == pytest.approx(mean, rel=1e-5)
    assert float(rows[1]["rms_error_mm_ci95"]) == pytest.approx(half, rel=1e-5)
    assert float(rows[1]["error_ratio"]) == pytest.approx(1.1, rel=1e-5)
    assert rows[0]["reference"] == "exact"


def test_paper_with_seeds_states_the_runs_per_cell(
        standin: dict, capsys: pytest.CaptureFixture[str]) -> None:
    standin["fail"] = set()
    assert main(["compare", "--preset", "tuna2013", "--paper", "--scenarios", "fixed-a2-top",
                 "--predictors", "exact", "--duration", "1", "--jobs", "2", "--seeds",
                 "3"]) == 0
    out = capsys.readouterr().out
    assert "ours = the mean ± the half-width of its 95 % interval over 3 runs (seeds 0–2)" in out
    mean, half = interval95([BASE_MM["exact"] * (1 + 0.1 * s) * 1.12 for s in range(3)])
    assert f"0.237 / {mean:.3f} ± {half:.3f} / {mean / 0.237:.2f}" in out


@pytest.fixture
def recording(tmp_path: Path) -> Path:
    t = np.arange(0.0, 6.0, 1 / 25)
    x = np.c_[2.5 * np.sin(2 * np.pi * 1.2 * t), 1.5 * np.sin(2 * np.pi * 1.2 * t + 1), 0 * t]
    path = tmp_path / "heart.csv"
    np.savetxt(path, np.c_[t, x], delimiter=",", header="t,x,y,z", comments="", fmt="%.6f")
    return path


def test_recordings_default_to_hold_and_ratios_to_hold(
        standin: dict, recording: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["compare", "--data", str(recording), "--duration", "2", "--jobs", "2"]) == 0
    out = capsys.readouterr().out
    ratio = out.split("ratio to hold")[1]
    assert "exact reads the recorded future" in ratio.splitlines()[0]
    for pred in ("exact", "one-step", "generalized", "ekf"):
        assert _row(ratio, pred)
    assert "0.50 / 0.50" in _row(ratio, "exact")  # 0.2 mm against hold's 0.4 mm
    assert max(map(len, out.splitlines())) <= MAX_WIDTH
    assert main(["compare", "--data", str(recording), "--duration", "2", "--jobs", "1",
                 "--json", "--quiet"]) == 0
    docs = json.loads(capsys.readouterr().out)["runs"]
    assert [d["predictor"] for d in docs] == list(compare.DATA_PREDICTORS)


@pytest.mark.slow
def test_first_progress_line_early_in_a_real_compare(tmp_path: Path) -> None:
    """The new-user check: a 2 × 2 compare's first stderr line before 60 % of its wall time."""
    err = tmp_path / "err.txt"
    start = time.monotonic()
    with err.open("w") as stream:
        proc = subprocess.Popen([sys.executable, "-m", "rhmpc.cli", "compare", "--scenarios",
                                 "fixed-a2-top,fixed-a1-top", "--predictors", "hold,one-step",
                                 "--duration", "4"], cwd=REPO, stdout=subprocess.DEVNULL,
                                stderr=stream)
        first = None
        while proc.poll() is None:
            if first is None and err.stat().st_size:
                first = time.monotonic() - start
            time.sleep(0.05)
    wall = time.monotonic() - start
    assert proc.returncode == 0, err.read_text()[-500:]
    assert first is not None and first < 0.6 * wall, (first, wall)


def test_an_unwritable_out_is_refused_before_any_run(
        standin: dict, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    standin["crash"] = {("hold", "fixed-a2-top")}  # a run would say so
    code = main(["compare", "--scenarios", "fixed-a2-top", "--predictors", "hold",
                 "--duration", "1", "--out", str(tmp_path / "missing" / "runs.json")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--out" in err
    assert "no such directory" in err


#: A compare of 8 runs whose ``hold`` runs end at once (each leaves a mark) and whose ``exact``
#: runs last two minutes; Ctrl-C as a terminal delivers it.
CTRL_C_SCRIPT = """
import signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)
from pathlib import Path
from rhmpc.cli import main
from rhmpc.compare import jobs as compare_jobs

def stand_in(job):
    if job.config.predictor == "exact":
        time.sleep(120)
    if job.key != "probe":  # the run that times the loop for the estimate
        Path(sys.argv[1], f"done{job.key}").write_text("")
    return compare_jobs.labelled({"predictor": job.config.predictor, "seed": job.config.seed,
                              "rms_error_mm": 0.4 + job.config.seed, "max_error_mm": 1.0,
                              "rms_effort_mNm": 10.0}, job)

compare_jobs.run_job = stand_in
sys.exit(main(["compare", "--scenarios", "fixed-a2-top", "--predictors", "hold,exact",
               "--seeds", "4", "--duration", "1", "--jobs", "2"]))
"""


@pytest.mark.slow
def test_ctrl_c_prints_the_runs_done_so_far(tmp_path: Path) -> None:
    """Ctrl-C with 4 of 8 runs done: the tables of those 4, a line that says so, exit 130, at
    once (the bound only catches a wait for the two-minute runs)."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen([sys.executable, "-c", CTRL_C_SCRIPT, str(tmp_path)], cwd=REPO,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        while len(list(tmp_path.glob("done*"))) < 4 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert len(list(tmp_path.glob("done*"))) == 4, "the four quick runs did not end"
        time.sleep(1.5)  # the runner has collected them (it looks every half second)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 130, err[-1000:]
    assert "interrupted with 4 of 8 runs done" in err and "Traceback" not in err
    assert "Each cell: mean ± half-width of the 95 % interval (Student t) over 4 runs" in out
    assert _row(out, "hold").split()[1:4] == ["1.900", "±", "2.054"]  # seeds 0–3 of hold
    assert _row(out, "exact").split()[1] == "-"  # not run


@pytest.mark.slow
def test_compare_on_a_dask_cluster(capsys: pytest.CaptureFixture[str]) -> None:
    """``--scheduler``: the runs go to the cluster's worker (two threads: one run at a time per
    process), and the table is the local one's."""
    distributed = pytest.importorskip("distributed")
    argv = ["compare", "--predictors", "hold,exact", "--scenarios", "fixed-a2-top",
            "--duration", "0.6", "--settling", "0.2", "--seeds", "2", "--json"]
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=True,
                                  host="127.0.0.1", dashboard_address=None,
                                  silence_logs=40) as cluster:
        assert main([*argv, "--scheduler", cluster.scheduler_address]) == 0
    captured = capsys.readouterr()
    remote = json.loads(captured.out)
    assert "on Dask cluster tcp://127.0.0.1" in captured.err
    assert main([*argv, "--jobs", "1"]) == 0
    local = json.loads(capsys.readouterr().out)
    assert [(r["predictor"], r["seed"], r["rms_error_mm"]) for r in remote["runs"]] == [
        (r["predictor"], r["seed"], r["rms_error_mm"]) for r in local["runs"]]
    assert remote["cells"] == local["cells"]
