"""`rhmpc tune` end to end on tiny closed-loop runs: local process pool, Dask cluster, report,
best-settings TOML through ``simulate --config``."""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import pytest

from rhmpc.cli import main
from rhmpc.cli.simulate import config_from_args
from rhmpc.experiment import RunConfig, load_config
from rhmpc.tuning.progress import speed_phrase
from rhmpc.tuning.spec import load_spec
from rhmpc.tuning.store import read_results
from tests.rhmpc.tuning.test_tune_spec import TINY as BASE_TINY

# The spec of test_tune_spec, with an objective that trades error against effort.
TINY = BASE_TINY.replace("{", "{{").replace("}", "}}") + """[objective]
metric = "rms_error_mm"
penalty = {{ metric = "rms_effort_mNm", weight = 1e-4, limit = 0.0 }}
{extra}
"""


def write_spec(tmp_path: Path, extra: str = "") -> Path:
    spec = tmp_path / "tiny.toml"
    spec.write_text(TINY.format(extra=extra))
    return spec


@pytest.mark.slow
def test_local_pool_report_and_best_toml(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    spec = write_spec(tmp_path)
    monkeypatch.chdir(tmp_path)  # the default results file goes to the current directory
    best = tmp_path / "best.toml"
    assert main(["tune", str(spec), "--jobs", "2", "--best-toml", str(best),
                 "--plot", str(tmp_path / "tune.png")]) == 0
    captured = capsys.readouterr()
    out = captured.out
    results = tmp_path / "tiny.results.jsonl"
    records = read_results(results).records
    assert len(records) == 2 and all(r["status"] == "ok" for r in records)
    # the speed as the records' own timings give it: faster, slower or about real time,
    # whichever this machine ran at
    simulated = sum(r["settings"]["loop"]["duration"] for r in records)
    speed = speed_phrase(simulated, sum(r["timing"]["wall_s"] for r in records))
    assert re.search(r"2 evaluation\(s\) in [\d.]+ s = \d+\.\d evaluations per minute; each "
                     r"ran " + re.escape(speed) + "\n", captured.err)
    r = records[0]
    for name in ("key", "point", "parameters", "scenario", "seed", "metrics", "timing",
                 "versions", "settings", "objective", "sweep"):
        assert name in r
    assert r["metrics"]["rms_error_mm"] > 0 and r["metrics"]["tick_us"]["p99"] > 0
    assert "rank" in out and "mpc.effort_weight" in out and "[mpc]" in out
    assert (tmp_path / "tune.png").stat().st_size > 1000

    # re-running skips everything that is done
    assert main(["tune", str(spec)]) == 0
    assert "to run 0" in capsys.readouterr().err
    assert len(read_results(results).records) == 2

    # the report from the results file alone agrees, and its JSON ranks by the objective
    assert main(["tune", "report", str(results), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    scores = [p["score_mean"] for p in doc["points"]]
    assert scores == sorted(scores) and len(scores) == 2
    winner = doc["points"][0]["parameters"]

    # the best-settings TOML round-trips through simulate --config
    loaded = load_config(best)
    base = load_spec(spec).base
    assert loaded == base.replace(**winner, scenario="fixed-a2-top", seed=0)
    assert loaded == RunConfig.from_dict(doc["best_settings"])
    args = type("Args", (), {"config": str(best), "duration": None, "settling": None,
                             "set": [], "data": None, "sensor": None})()
    assert config_from_args(args) == loaded


@pytest.mark.slow
def test_dask_local_cluster(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    distributed = pytest.importorskip("distributed")
    spec = write_spec(tmp_path)
    results = tmp_path / "dask.jsonl"
    # two threads in one worker process: evaluations must not run concurrently in a process
    # (building two MPCs at once crashes inside CasADi), rhmpc.tuning serialises them
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=True,
                                  host="127.0.0.1", dashboard_address=None,
                                  silence_logs=40) as cluster:
        code = main(["tune", str(spec), "--scheduler", cluster.scheduler_address,
                     "--results", str(results)])
    assert code == 0
    records = read_results(results).records
    assert len(records) == 2 and all(r["status"] == "ok" for r in records)
    assert os.getpid() not in {r["timing"]["pid"] for r in records}  # ran on the worker
    assert "rank" in capsys.readouterr().out
