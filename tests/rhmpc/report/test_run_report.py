"""The run's summary names who served the refreshes, and sets the controller's tick (the
library's, timed inside C) against the real-time budget."""

from __future__ import annotations

import pytest

from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.report.summary import format_summary


@pytest.fixture(scope="module")
def doc() -> dict:
    config = RunConfig(predictor="one-step").replace(**{"loop.duration": 0.6,
                                                        "loop.settling": 0.2})
    return run_experiment(config)[1]


def _line(text: str, start: str) -> str:
    return next(line for line in text.splitlines() if line.lstrip().startswith(start))


def test_the_tick_is_set_against_the_budget_with_the_python_predictor(doc: dict) -> None:
    text = format_summary(doc)
    assert doc["implementation"] == "python"
    assert "controller the library, the run's predictor in Python, seed 0" in text.splitlines()[0]
    line = _line(text, "controller tick")
    assert "(budget 500 µs, refreshes included, the Python predictor's too)" in line


def test_the_tick_with_the_librarys_own_predictor(doc: dict) -> None:
    text = format_summary({**doc, "implementation": "c"})
    assert "controller the library with its own RLS predictor, seed 0" in text.splitlines()[0]
    assert "(budget 500 µs, refreshes included)" in _line(text, "controller tick")


def test_a_run_shorter_than_the_gates_learning_says_so(doc: dict) -> None:
    gate = doc["outlier_gate"]
    assert gate["floor_mm"] is None and gate["calibration_s"] == 10.0  # 2 × 5 s, the default
    line = _line(format_summary(doc), "outlier gate")
    assert "not armed: it learns its floor over the first 10 s of samples" in line
    assert "calibrating" not in line
