"""How long a comparison takes: said before its first run, kept up to date as runs finish.

A run of predictor p on a column lasting D simulated seconds is estimated as

.. math::

    \\hat T = T_b + D\\,(\\ell + f\\,u_p) + F_p,

with T_b the time to build a run and ℓ the loop's wall time per simulated second, both timed
on a :data:`PROBE_S`-second run of ``hold`` (the cheapest predictor) on the first column; f the
predictor's refreshes per simulated second (its clock); u_p one refresh of p — its update and
forecast of one sample — timed on heart-like samples at its period (a combination: the sum
of its members'; a fitted network: its probe's, :func:`rhmpc.experiment.fit_plan.step_seconds`),
or on a split, on the recording's (the open loop's plan, :mod:`rhmpc.openloop.plan`); and F_p
the fit before the run (:func:`rhmpc.experiment.fit_plan.plan_fits`: 0 for a model loaded or
shared).

The whole is the open loops' estimate plus the runs' on W workers, scheduled longest first
(:func:`makespan`). As runs finish, their measured time (``build_s`` + ``wall_s`` of each
document) over their estimate scales what is left (:class:`Remaining`): the bar's estimate
follows the runs, whatever their lengths.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from rhmpc.compare.jobs import Job
from rhmpc.experiment.fit_plan import duration, plan_fits, step_seconds
from rhmpc.predictors import LEARNED, make_predictor
from rhmpc.predictors.registry import combination_members

__all__ = ["PROBE_S", "Probe", "Remaining", "heart_rows", "job_estimates", "makespan",
           "probe"]

#: The simulated length of the probe run [s], and its settling [s].
PROBE_S, PROBE_SETTLING_S = 2.0, 1.0
#: Samples a predictor's step is timed on (after :data:`~rhmpc.experiment.fit_plan.STEP_SAMPLES`
#: of them, the rest the length of a fit's probe series where no settling is longer).
HEART_ROWS = 200


@dataclass(frozen=True)
class Probe:
    """What the probe run measured.

    Attributes
    ----------
    build_s : float
        T_b, the time to build a run [s].
    loop_s : float
        ℓ, the loop's wall time per simulated second [s/s].
    refresh_hz : float
        f, the predictor's refreshes per simulated second [Hz].
    rows : ndarray, shape (n, 1, 3)
        Heart-like samples at the predictor's period [m] (:func:`heart_rows`), for timing each
        predictor's step.
    """

    build_s: float
    loop_s: float
    refresh_hz: float
    rows: np.ndarray


def probe(job: Job) -> Probe | None:
    """A :data:`PROBE_S`-second run of ``hold`` on ``job``'s column, timed
    (:func:`rhmpc.compare.jobs.run_job`); None if its document says nothing of its time."""
    from rhmpc.compare import jobs

    c = job.config
    config = c.replace(predictor="hold", predictor_settings={}, **{
        "loop.duration": min(PROBE_S, c.loop.duration),
        "loop.settling": min(PROBE_SETTLING_S, c.loop.duration / 2)})
    doc = jobs.run_job(Job("probe", job.column, config))
    try:
        dt = float(doc["predictor_clock"]["dt_s"])
        return Probe(float(doc["build_s"]), float(doc["wall_s"]) / config.loop.duration,
                     1.0 / dt, heart_rows(dt, HEART_ROWS))
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        return None


def heart_rows(dt: float, n: int) -> np.ndarray:
    """(n, 1, 3) heart-like samples [m] every ``dt`` seconds: 1.2 Hz and its harmonics, and
    breathing at 0.25 Hz, a few millimetres (what a predictor's step is timed on)."""
    t = np.arange(n) * dt
    beat, breath = 2 * np.pi * 1.2 * t, 2 * np.pi * 0.25 * t
    z = 1e-3 * np.stack([3 * np.sin(beat) + np.sin(2 * beat) + 2 * np.sin(breath),
                         2 * np.cos(beat) + 0.5 * np.cos(3 * beat) + np.sin(breath),
                         np.sin(beat + 0.4) + 1.5 * np.sin(breath + 0.6)], axis=1)
    return z[:, None, :]


def _cost(name: str, measured: Probe, depth: int, settling: float, seed: int,
          steps: dict[str, float]) -> tuple[float, float]:
    """(u_p [s], F_p [s]) of predictor ``name``: one refresh, and its fit before the run on a
    settling window of ``settling`` seconds (0 where ``steps`` has it: fitted elsewhere)."""
    if name in steps:
        return steps[name], 0.0
    if name == "exact":  # the true future, read: no predictor
        return 0.0, 0.0
    dt = 1.0 / measured.refresh_hz
    if name in LEARNED:
        frames = max(measured.rows.shape[0], round(settling * measured.refresh_hz))
        rows = heart_rows(dt, frames)
        with warnings.catch_warnings():  # a probe of a short settling window: the run warns
            warnings.simplefilter("ignore")
            (plan,) = plan_fits([name], dt, [rows], depth, seed) or (None,)
        if plan is None:
            return 0.0, 0.0
        return plan.step_s or 0.0, plan.estimate_s or 0.0
    if name == "combination":
        costs = [_cost(m, measured, depth, settling, seed, steps)
                 for m in combination_members()]
        return sum(c[0] for c in costs), sum(c[1] for c in costs)
    return step_seconds(make_predictor(name, dt=dt), measured.rows, depth), 0.0


def job_estimates(todo: Sequence[Job], measured: Probe,
                  steps: dict[str, dict[str, float]] | None = None) -> list[float]:
    """T̂ of each job (the module's equation). ``steps``: column → name → u_p already timed
    (a split's open loop, whose fitted models the runs load)."""
    costs: dict[tuple[str, str], tuple[float, float]] = {}
    out = []
    for job in todo:
        c, name = job.config, job.config.predictor
        key = (job.column if steps and job.column in steps else "", name)
        if key not in costs:
            loaded = bool(c.predictor_settings.get("model") or c.predictor_settings.get("models"))
            u, fit = _cost(name, measured, c.reference.prediction_points, c.loop.settling_s,
                           c.seed, (steps or {}).get(job.column, {}))
            costs[key] = (u, 0.0 if loaded else fit)
        u, fit = costs[key]
        D = c.loop.duration
        out.append(measured.build_s + D * (measured.loop_s + measured.refresh_hz * u) + fit)
    return out


def makespan(estimates: Sequence[float], workers: int) -> float:
    """The time ``workers`` take for runs of ``estimates`` [s], each run given to the worker
    free first, the longest first (LPT scheduling)."""
    free = [0.0] * max(1, workers)
    for t in sorted(estimates, reverse=True):
        i = int(np.argmin(free))
        free[i] += t
    return max(free)


@dataclass
class Remaining:
    """The time left, from the estimates of the runs and the measured time of those done.

    The runs left take their estimates times c = Σ measured / Σ estimated over the runs done
    (1 before the first), on ``workers`` (:func:`makespan`), less what the runs in flight have
    already spent since the last one finished."""

    estimates: dict[str, float]
    workers: int
    done: dict[str, float] = field(default_factory=dict)
    last: float = field(default_factory=lambda: time.monotonic())

    def finished(self, key: str, measured: float | None) -> None:
        """Run ``key`` finished after ``measured`` seconds (None: unknown, a failed run)."""
        self.done[key] = self.estimates.get(key, 0.0) if measured is None else measured
        self.last = time.monotonic()

    @property
    def scale(self) -> float:
        """c, the measured over the estimated time of the runs done."""
        estimated = sum(self.estimates[k] for k in self.done)
        return sum(self.done.values()) / estimated if estimated > 0 else 1.0

    def seconds(self) -> float:
        """The time left [s]."""
        left = [t * self.scale for k, t in self.estimates.items() if k not in self.done]
        if not left:
            return 0.0
        return max(0.0, makespan(left, min(self.workers, len(left)))
                   - (time.monotonic() - self.last))

    def text(self) -> str:
        """``about 4.2 min left`` (nothing without estimates)."""
        return f"about {duration(self.seconds())} left" if self.estimates else ""
