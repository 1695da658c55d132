"""`rhmpc tune` results file and runner: atomic lines, interruption, resume, failures, dead workers.

These use a stand-in evaluation (no closed loop) so they run in a fraction of a second, except
the dead-worker test, which spawns real worker processes.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import tomllib
from collections import Counter
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

import pytest

from rhmpc.errors import UsageError
from rhmpc.tuning.evaluate import Task, record_for
from rhmpc.tuning.runner import pending, process_pool, run_sweep
from rhmpc.tuning.spec import parse_spec
from rhmpc.tuning.store import ResultsWriter, read_results

SPEC = """
[parameters]
"mpc.effort_weight" = [1e-5, 1e-4, 1e-3]
"mpc.rate_weight" = [0.01, 0.1]
[evaluate]
scenarios = ["fixed-a1-top", "fixed-a2-top"]
"""


def tasks() -> list[Task]:
    return parse_spec(tomllib.loads(SPEC), where="spec.toml").tasks()


def fake_evaluate(task: Task, extra: dict | None = None) -> dict:
    """A deterministic stand-in for a closed-loop run; fails for effort_weight 1e-3, rate 0.01."""
    p = task.parameters
    if p["mpc.effort_weight"] == 1e-3 and p["mpc.rate_weight"] == 0.01:
        return record_for(task, "failed", **(extra or {}), error="RuntimeError: boom")
    error = 0.2 + 100 * p["mpc.effort_weight"] + 0.1 * p["mpc.rate_weight"] + 0.01 * task.index
    return record_for(task, "ok", **(extra or {}),
                      metrics={"rms_error_mm": error, "rms_effort_mNm": 300.0 / (1 + error)})


def crashing_evaluate(task: Task, extra: dict | None = None) -> dict:
    """Kills its worker process for one point (a segfault's stand-in)."""
    if task.parameters["mpc.effort_weight"] == 1e-4 and task.parameters["mpc.rate_weight"] == 0.1:
        os._exit(3)
    return fake_evaluate(task, extra)


def threads() -> ThreadPoolExecutor:
    return ThreadPoolExecutor(max_workers=2)


def keys_in(path: Path) -> list[str]:
    return [r["key"] for r in read_results(path).records]


def test_interrupt_then_resume_gives_the_union(tmp_path: Path) -> None:
    results = tmp_path / "r.jsonl"
    all_tasks = tasks()
    seen = []

    def stop_after_three(record: dict) -> None:
        seen.append(record["key"])
        if len(seen) == 3:
            raise KeyboardInterrupt

    with ResultsWriter(results) as w:
        out = run_sweep(all_tasks, w, threads, window=2, evaluate=fake_evaluate,
                        on_result=stop_after_three)
    assert out.interrupted
    first = keys_in(results)
    assert 3 <= len(first) < len(all_tasks)  # whatever finished meanwhile is kept too
    assert first[:3] == seen
    todo, ok, failed = pending(all_tasks, read_results(results))
    assert len(todo) == len(all_tasks) - len(first)
    with ResultsWriter(results) as w:
        out = run_sweep(todo, w, threads, window=2, evaluate=fake_evaluate)
    assert not out.interrupted and out.written == len(todo)
    assert out.elapsed_s > 0  # throughput as `rhmpc tune` prints it
    assert out.evaluations_per_minute == pytest.approx(60 * len(todo) / out.elapsed_s, rel=1e-12)
    final = keys_in(results)
    assert Counter(final) == Counter(t.key for t in all_tasks)  # the union, no duplicates
    # a third run has nothing to do
    todo, ok, failed = pending(all_tasks, read_results(results))
    assert todo == [] and ok == 10 and failed == 2


def test_failures_recorded_not_retried_unless_asked(tmp_path: Path) -> None:
    results = tmp_path / "r.jsonl"
    with ResultsWriter(results) as w:
        out = run_sweep(tasks(), w, threads, window=3, evaluate=fake_evaluate,
                        extra={"sweep": "t"})
    assert (out.ok, out.failed) == (10, 2)
    failed = [r for r in read_results(results).records if r["status"] == "failed"]
    assert {r["error"] for r in failed} == {"RuntimeError: boom"}
    assert all(r["sweep"] == "t" and r["versions"]["python"] for r in failed)
    todo, ok, n_failed = pending(tasks(), read_results(results))
    assert (todo, ok, n_failed) == ([], 10, 2)
    todo, _, _ = pending(tasks(), read_results(results), retry_failed=True)
    assert len(todo) == 2


def test_truncated_last_line_is_tolerated(tmp_path: Path) -> None:
    results = tmp_path / "r.jsonl"
    all_tasks = tasks()
    with ResultsWriter(results) as w:
        run_sweep(all_tasks[:4], w, threads, window=2, evaluate=fake_evaluate)
    text = results.read_text()
    results.write_text(text + text.splitlines()[0][:40])  # a crash mid-write
    data = read_results(results)
    assert len(data.records) == 4 and data.bad_lines == 1
    todo, ok, _ = pending(all_tasks, data)
    assert ok == 4
    with ResultsWriter(results) as w:  # appends start on a fresh line
        run_sweep(todo, w, threads, window=2, evaluate=fake_evaluate)
    data = read_results(results)
    assert data.bad_lines == 1
    assert Counter(r["key"] for r in data.records) == Counter(t.key for t in all_tasks)
    for line in results.read_text().splitlines()[5:]:
        json.loads(line)


def test_one_writer_at_a_time(tmp_path: Path) -> None:
    with ResultsWriter(tmp_path / "r.jsonl"), pytest.raises(UsageError, match="another"):
        ResultsWriter(tmp_path / "r.jsonl").open()


def test_dead_worker_is_retried_then_recorded(tmp_path: Path) -> None:
    results = tmp_path / "r.jsonl"
    subset = [t for t in tasks() if t.parameters["mpc.rate_weight"] == 0.1
              and t.parameters["mpc.effort_weight"] <= 1e-4 and t.index == 0]  # 2 points

    def forked_pool() -> ProcessPoolExecutor:  # fork: quick to start; same runner path
        return ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork"))

    with ResultsWriter(results) as w:
        out = run_sweep(subset, w, forked_pool, window=1, evaluate=crashing_evaluate,
                        max_attempts=2)
    records = read_results(results).records
    assert Counter(r["key"] for r in records) == Counter(t.key for t in subset)
    failed = [r for r in records if r["status"] == "failed"]
    assert len(failed) == 1 and "worker died 2 times" in failed[0]["error"]
    assert failed[0]["parameters"] == {"mpc.effort_weight": 1e-4, "mpc.rate_weight": 0.1}
    assert out.ok == 1 and out.pool_restarts == 2


def test_process_pool_workers_ignore_sigint() -> None:
    with process_pool(1) as pool:
        assert pool.submit(signal.getsignal, signal.SIGINT).result() == signal.SIG_IGN
