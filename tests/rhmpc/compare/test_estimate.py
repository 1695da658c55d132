"""How long a comparison takes (rhmpc.compare.estimate): each run's estimate from the probe's
numbers, the runs' schedule on the workers, the time left scaled by the runs done."""

from __future__ import annotations

import numpy as np
import pytest

from rhmpc.compare import estimate
from rhmpc.compare.estimate import Probe, Remaining, heart_rows, job_estimates, makespan
from rhmpc.compare.jobs import Job, make_jobs, scenario_columns
from rhmpc.experiment import RunConfig


def jobs(predictors: tuple[str, ...], duration: float = 10.0) -> list[Job]:
    base = RunConfig().replace(**{"loop.duration": duration})
    return make_jobs(base, scenario_columns(["fixed-a2-top"]), predictors, [0])


def test_a_run_is_its_build_its_loop_and_its_refreshes() -> None:
    measured = Probe(build_s=2.0, loop_s=0.5, refresh_hz=100.0, rows=heart_rows(0.01, 200))
    exact, ekf = job_estimates(jobs(("exact", "ekf")), measured)
    assert exact == 2.0 + 10.0 * 0.5  # the true future, read: no refresh costs
    assert ekf > exact  # each of its 1 000 refreshes an update and a forecast


def test_a_split_takes_the_open_loop_s_steps_and_no_fit() -> None:
    measured = Probe(2.0, 0.5, 25.0, heart_rows(0.04, 200))
    (lstm,) = job_estimates(jobs(("lstm",)), measured, {"fixed-a2-top": {"lstm": 0.02}})
    assert lstm == pytest.approx(2.0 + 10.0 * (0.5 + 25.0 * 0.02), rel=1e-12)


def test_the_runs_are_scheduled_longest_first() -> None:
    assert makespan([5, 4, 3, 3, 3], 2) == 10  # 5 + 3 and 4 + 3 + 3 (the best is 9: LPT)
    assert makespan([9, 1, 1, 1], 3) == 9
    assert makespan([2, 2], 1) == 4 and makespan([], 2) == 0


def test_the_time_left_scales_with_the_runs_done(monkeypatch: pytest.MonkeyPatch) -> None:
    now = [100.0]
    monkeypatch.setattr(estimate.time, "monotonic", lambda: now[0])
    left = Remaining({"a": 10.0, "b": 30.0, "c": 30.0}, workers=1)
    assert left.seconds() == 70.0 and left.text() == "about 70 s left"
    now[0] = 115.0
    left.finished("a", 20.0)  # twice its estimate: the rest takes twice theirs
    assert left.scale == 2.0 and left.seconds() == 120.0
    now[0] = 175.0
    assert left.seconds() == 60.0  # what the run in flight spent since is done
    assert Remaining({}, 2).text() == ""


def test_the_steps_are_timed_on_heart_like_samples() -> None:
    rows = heart_rows(0.04, 100)
    assert rows.shape == (100, 1, 3) and np.all(np.abs(rows) < 8e-3)
    np.testing.assert_allclose(rows[0, 0], 1e-3 * np.array([0.0, 2.5, np.sin(0.4) + 1.5 *
                                                            np.sin(0.6)]), atol=1e-15)
