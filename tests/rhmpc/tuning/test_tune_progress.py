"""`rhmpc tune` around its runs: the bound on a sweep's size, progress while it runs, times in
words, log axes and a heat map in its figure."""

from __future__ import annotations

import math
import time
import tomllib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

from rhmpc.errors import UsageError
from rhmpc.tuning.figure import log_spaced, objective_figure
from rhmpc.tuning.objective import Objective
from rhmpc.tuning.progress import format_duration, speed_phrase
from rhmpc.tuning.report import PointSummary
from rhmpc.tuning.runner import run_sweep
from rhmpc.tuning.spec import MAX_EVALUATIONS, parse_spec
from rhmpc.tuning.store import ResultsWriter

RANDOM = """
[base.loop]
duration = 20.0
[parameters]
"mpc.effort_weight" = {{ low = 1e-6, high = 1e-2, scale = "log" }}
[sampler]
method = "random"
budget = {budget}
[evaluate]
scenarios = ["fixed-a1-top", "fixed-a2-top"]
"""


@pytest.mark.parametrize(("seconds", "text"), [
    (0.004, "0.004 s"), (0.46, "0.46 s"), (4.66, "4.7 s"), (8.0, "8 s"), (47.2, "47 s"),
    (83.4, "1 min 23 s"), (725, "12 min 5 s"), (3.2 * 3600, "3 h 12 min"),
    (4.2 * 86400, "4.2 days"), (1e10, "320 years"), (math.inf, "?"),
])
def test_durations_are_rounded(seconds: float, text: str) -> None:
    assert format_duration(seconds) == text


@pytest.mark.parametrize(("simulated", "wall", "text"), [
    (14.3, 1.0, "14× faster than real time"), (4.1, 1.0, "4.1× faster than real time"),
    (1.0, 2.3, "2.3× slower than real time"), (1.0, 1.02, "about real time"),
    (1.0, 0.0, "speed unknown"),
])
def test_speed_says_faster_or_slower(simulated: float, wall: float, text: str) -> None:
    assert speed_phrase(simulated, wall) == text


def test_a_huge_budget_is_refused_at_once_with_the_time_it_would_take() -> None:
    start = time.perf_counter()
    with pytest.raises(UsageError) as err:
        parse_spec(tomllib.loads(RANDOM.format(budget=10**9)), where="huge.toml")
    assert time.perf_counter() - start < 1.0  # no point is drawn
    message = str(err.value)
    assert "\n" not in message and message.startswith("huge.toml: sampler.budget")
    assert "2,000,000,000 evaluations" in message
    assert f"limit of {MAX_EVALUATIONS:,}" in message and "years" in message


def test_a_huge_grid_is_refused_before_it_is_listed() -> None:
    text = RANDOM.format(budget=1).replace('scale = "log" }', 'scale = "log", num = 100000 }')
    text = text.replace('method = "random"\nbudget = 1', 'method = "grid"')
    with pytest.raises(UsageError, match=r"a grid of 100000 points × 2 evaluation"):
        parse_spec(tomllib.loads(text), where="grid.toml")


@pytest.mark.slow
def test_the_largest_allowed_budget_parses() -> None:
    spec = parse_spec(tomllib.loads(RANDOM.format(budget=MAX_EVALUATIONS // 2)))
    assert spec.budget == MAX_EVALUATIONS // 2


def test_cli_refuses_a_huge_budget_in_one_line(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    from rhmpc.cli import main

    spec = tmp_path / "huge.toml"
    spec.write_text(RANDOM.format(budget=10**9))
    assert main(["tune", str(spec), "--results", str(tmp_path / "r.jsonl")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "limit of" in err and "would take" in err
    assert not (tmp_path / "r.jsonl").exists()


class _Task(NamedTuple):
    key: str


def _slow_evaluate(task: _Task, extra: dict | None = None) -> dict:
    time.sleep(0.6)
    return {"key": task.key, "status": "ok"}


@pytest.mark.slow
def test_heartbeat_runs_while_evaluations_are_in_flight(tmp_path: Path) -> None:
    beats = []
    with ResultsWriter(tmp_path / "r.jsonl") as writer:
        out = run_sweep([_Task("1"), _Task("2")], writer, lambda: ThreadPoolExecutor(1), window=1,
                        evaluate=_slow_evaluate, heartbeat=lambda: beats.append(1))
    assert out.ok == 2 and len(beats) >= 3  # every 0.5 s, and after each result


def _summaries(grid: bool) -> list[PointSummary]:
    """A 3 × 4 grid (or 12 random points) over two log-spaced weights, a bowl in log space."""
    rng = np.random.default_rng(0)
    if grid:
        pairs = [(a, b) for a in (1e-4, 1e-3, 1e-2) for b in (0.01, 0.03, 0.1, 0.3)]
    else:
        pairs = [(10 ** rng.uniform(-4, -2), 10 ** rng.uniform(-2, -0.5)) for _ in range(12)]
    out = []
    for i, (a, b) in enumerate(pairs):
        score = 0.2 + 0.01 * (math.log10(a) + 3) ** 2 + 0.02 * (math.log10(b) + 1.5) ** 2
        out.append(PointSummary(f"p{i}", {"mpc.effort_weight": a, "mpc.rate_weight": b},
                                n_ok=1, score_mean=score, score_std=0.0))
    return sorted(out, key=lambda s: s.score_mean)


def _labels(axis) -> list[str]:
    return [t.get_text() for t in axis.get_ticklabels() if t.get_text()]


@pytest.mark.parametrize("grid", [True, False], ids=["grid", "random"])
def test_figure_log_axes_readable_ticks_and_heat_map(grid: bool) -> None:
    import matplotlib.pyplot as plt

    fig = objective_figure(_summaries(grid), Objective(), title="t")
    fig.canvas.draw()
    panels = [ax for ax in fig.axes if ax.get_label() != "<colorbar>"]
    assert len(panels) == 3  # one per parameter, and the heat map
    for ax in panels[:2]:
        assert ax.get_xscale() == "log"
        assert len(_labels(ax.xaxis)) >= 3
    heat = panels[2]
    if grid:
        assert heat.images and _labels(heat.xaxis) == ["0.0001", "0.001", "0.01"]
        assert _labels(heat.yaxis) == ["0.01", "0.03", "0.1", "0.3"]
        assert len(heat.texts) == 12  # every cell annotated
    else:
        assert heat.collections and heat.get_xscale() == heat.get_yscale() == "log"
        assert len(_labels(heat.xaxis)) >= 3 and len(_labels(heat.yaxis)) >= 2
    plt.close(fig)


def test_log_spacing_is_recognised() -> None:
    assert log_spaced([1e-4, 1e-3, 1e-2])
    assert log_spaced([0.01, 0.03, 0.1, 0.3, 1.0])
    assert not log_spaced([1, 2, 3, 4])
    assert not log_spaced([0.0, 1.0, 2.0])
    assert not log_spaced(["a", "b"])


def test_an_unwritable_plot_is_refused_before_the_sweep(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from rhmpc.cli import main

    spec = tmp_path / "small.toml"
    spec.write_text(RANDOM.format(budget=2))
    results = tmp_path / "r.jsonl"
    assert main(["tune", str(spec), "--results", str(results), "--plot",
                 str(tmp_path / "missing" / "p.png")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--plot" in err and not results.exists()
