"""The run's summary names the controller that ran, and sets only the deployable C's tick
against the real-time budget: the Python reference's tick reads as the speed of a study."""

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


def test_the_python_reference_tick_is_a_study_speed_not_a_budget(doc: dict) -> None:
    text = format_summary(doc)
    assert doc["implementation"] == "python"
    assert "controller Python reference, seed 0" in text.splitlines()[0]
    line = _line(text, "study speed")
    assert line.split()[2:4] == ["Python", "reference"] and "budget" not in line.split("(")[0]
    assert "not the deployable's: rhmpc bench --controller c and simulate --controller c" in line
    assert "controller tick" not in text


def test_the_deployable_tick_is_set_against_the_budget(doc: dict) -> None:
    text = format_summary({**doc, "implementation": "c"})
    assert "controller deployable C (rhmpc export), seed 0" in text.splitlines()[0]
    assert "(the deployable C: budget 500 µs, refreshes included)" in _line(text,
                                                                             "controller tick")
    assert "study speed" not in text
