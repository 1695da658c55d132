"""Fitting the learned predictors before they run (an open-loop study, or a closed loop's
settling window): what is fitted, on which frames, why in two rounds, and how long it will
take, said before the fits start.

A network predictor (:class:`rhmpc.predictors.learned.settings.NetworkSettings`) trains
``ensemble`` networks per head (one head per lead with ``heads = "per-lead"``, one for every
lead with ``"joint"``), for ``epochs`` epochs, in two rounds when ``validation`` = v > 0: a
*validation round* on the first 1 − v of each training series, whose forecasts on the last v
give the out-of-sample error that an online combination starts from, then the *final round*
on every frame. Its fitting time is estimated before it starts from one network trained on the
same frames for 1 and for :data:`PROBE_EPOCHS` epochs, after a first fit that imports the
network's library (the difference leaves out what does not grow with the epochs):

.. math::

    t_{\\text{epoch}} = \\frac{t_{K} - t_1}{K - 1}, \\qquad
    \\hat T = t_{\\text{epoch}} \\cdot E \\cdot M \\cdot \\bigl((1 - v)\\,[v > 0] + 1\\bigr),

with K = :data:`PROBE_EPOCHS`, E the epochs and M the networks per round. The ridge
regressions fit in about a second and are not probed. A model fitted on the same samples
before is loaded from the cache instead (:mod:`rhmpc.experiment.model_cache`): no probe, no fit.

Its forecasts cost, per sample, M times one network's step (each network steps once per
sample), timed on :data:`STEP_SAMPLES` samples of the probe (or of the cached model itself):
the scoring's estimate of :func:`step_seconds`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.predictors import LEARNED, make_predictor, settings_for

__all__ = ["PROBE_EPOCHS", "STEP_SAMPLES", "FitPlan", "describe", "duration", "fit_all",
           "plan_fits", "step_seconds"]

#: K, the epochs of the longer probe network.
PROBE_EPOCHS = 5
#: Samples a predictor's step (update and forecast) is timed on for an estimate.
STEP_SAMPLES = 40


@dataclass(frozen=True)
class FitPlan:
    """How one fitted predictor will be fitted.

    Attributes
    ----------
    name : str
        The predictor.
    networks : int
        Networks per round (0: not a network predictor).
    validation : float
        v, the fraction held out in the validation round (0: one round).
    estimate_s : float or None
        The estimated fitting time [s] (None: not probed, about a second; 0 when cached).
    cached : Path or None
        The model fitted on the same samples before, which is loaded instead of fitted.
    step_s : float or None
        The estimated time of one sample's update and forecast [s] (None: not timed).
    """

    name: str
    networks: int
    validation: float
    estimate_s: float | None
    cached: Path | None = None
    step_s: float | None = None

    @property
    def rounds(self) -> int:
        return 2 if self.networks and self.validation > 0 else 1


def _networks(name: str, leads: int) -> tuple[int, float, int]:
    """(networks per round, validation fraction, epochs) of a network predictor; (0, v, 0)
    for another fitted one."""
    s = settings_for(name, leads=leads)
    if not hasattr(s, "epochs"):
        return 0, float(getattr(s, "validation", 0.0)), 0
    heads = leads if s.heads == "per-lead" else 1
    return s.ensemble * heads, float(s.validation), int(s.epochs)


def plan_fits(names: Sequence[str], period: float, series: list[np.ndarray], leads: int,
              seed: int, predictors: dict | None = None) -> list[FitPlan]:
    """The plan of every fitted predictor of ``names``: loaded from the cache when fitted on
    ``series`` before, else each network predictor's time estimated from one timed epoch of
    one network on ``series`` (the module's equation). ``predictors``: name → the predictor
    to be fitted, where it is not the one :func:`fit_all` makes."""
    from rhmpc.experiment.model_cache import lookup

    out = []
    for name in names:
        if name not in LEARNED:
            continue
        networks, validation, epochs = _networks(name, leads)
        own = (predictors or {}).get(name) or _fresh(name, period, leads, seed)
        cached = lookup(own, series)
        estimate = step = None
        if cached is not None:
            estimate = 0.0
            if networks:
                loaded = make_predictor(name, dt=period, model=str(cached))
                step = step_seconds(loaded, series[0], leads)
        elif networks:
            _probe(name, period, series, seed, 1)  # the first fit of a process imports
            t1 = _probe(name, period, series, seed, 1)[0]
            tk, probe = _probe(name, period, series, seed, PROBE_EPOCHS)
            epoch = max(tk - t1, 0.0) / (PROBE_EPOCHS - 1)
            estimate = epoch * epochs * networks * ((1.0 - validation) * (validation > 0) + 1)
            step = networks * step_seconds(probe, series[0], 1)
        out.append(FitPlan(name, networks, validation, estimate, cached, step))
    return out


def _fresh(name: str, period: float, leads: int, seed: int):
    """The predictor ``name`` as :func:`fit_all` makes it, before its fit."""
    extra = {"seed": seed} if "seed" in LEARNED[name].settings.__dataclass_fields__ else {}
    return make_predictor(name, dt=period, leads=leads, **extra)


def _probe(name: str, period: float, series: list[np.ndarray], seed: int, epochs: int):
    """(seconds, network): one network of ``name`` fitted on ``series`` for ``epochs``
    epochs, and how long it took."""
    probe = make_predictor(name, dt=period, leads=1, epochs=epochs, validation=0.0, ensemble=1,
                           heads="per-lead", seed=seed)
    tic = time.perf_counter()
    probe.fit(series)
    return time.perf_counter() - tic, probe


def step_seconds(predictor, rows: np.ndarray, depth: int, samples: int = STEP_SAMPLES) -> float:
    """The mean time of one sample's ``update`` and ``predict(depth)`` [s], timed on the
    first ``samples`` rows of ``rows`` ((T, P, d) [m], the POI first: the others are fed to a
    predictor that reads them), after the first (which allocates)."""
    rows = np.asarray(rows, dtype=float)
    z, others = rows[:, 0], (rows[:, 1:] if rows.shape[1] > 1 else None)
    n = min(samples + 1, rows.shape[0])
    spent, timed = 0.0, 0
    for i in range(n):
        tic = time.perf_counter()
        predictor.update(z[i], None if others is None or not predictor.multi_point else
                         others[i])
        try:
            predictor.predict(depth)
        except RuntimeError:  # no valid sample yet
            continue
        if i:
            spent, timed = spent + time.perf_counter() - tic, timed + 1
    predictor.reset()
    return spent / timed if timed else 0.0


def fit_all(plans: Sequence[FitPlan], period: float, series: list[np.ndarray], leads: int,
            seed: int, progress: Callable[[str], None] | None = None,
            save: Path | None = None, label: str = "") -> dict:
    """name → (fitted predictor, seconds, cached model or None): each planned predictor
    forecasting leads 1 … ``leads`` directly, fitted on ``series`` with the study's ``seed``
    (its progress told round by round), or loaded from the cache where it was fitted on them
    before (:func:`rhmpc.experiment.model_cache.fit_or_load`); each saved in the folder
    ``save`` if given (``LABEL.NAME.npz``)."""
    from rhmpc.experiment.model_cache import fit_or_load

    out = {}
    for plan in plans:
        p = _fresh(plan.name, period, leads, seed)
        tic = time.perf_counter()
        cached = fit_or_load(p, series, None if progress is None else _rounds(plan, progress))
        out[plan.name] = (p, time.perf_counter() - tic, cached)
        if save is not None:
            p.save(save / f"{io.file_stem(label)}.{plan.name}{p.SUFFIX}")
    return out


def _rounds(plan: FitPlan, progress: Callable[[str], None]) -> Callable[[str], None]:
    """``progress`` with each network's line named by its round (validation, then final)."""
    round_ = 0

    def say(text: str) -> None:
        nonlocal round_
        if text.startswith("network 1/"):
            round_ += 1
        if plan.rounds == 2 and text.startswith("network "):
            which = "validation round" if round_ == 1 else "final round"
            text = f"{which}, {text}"
        progress(f"fit {plan.name}: {text}")

    return say


def duration(seconds: float) -> str:
    """``8 s``, ``57 s``, ``4.2 min``: an estimate, rounded."""
    return f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.1f} min"


def _seconds(plan: FitPlan) -> str:
    if plan.cached is not None:
        return "from the cache"
    return "about a second" if plan.estimate_s is None else duration(plan.estimate_s)


def describe(plans: Sequence[FitPlan], where: str, frames: int | None,
             omitted: Sequence[FitPlan] = (), every: Sequence[str] = ()) -> list[str]:
    """What is fitted, on which frames, why in two rounds, and how long: the lines said
    before the fits start.

    Parameters
    ----------
    plans : sequence of FitPlan
        The fits to run.
    where : str
        The frames they are fitted on, in words (``"frames 0–599 of rec.mat"``).
    frames : int or None
        Frames of one training series (None: several recordings), for the rounds' frames.
    omitted : sequence of FitPlan
        Fitted predictors left out of the default set, with their estimates.
    every : sequence of str
        The default set, for the option that adds the omitted ones.
    """
    fits = [p for p in plans if p.cached is None]
    loads = [p for p in plans if p.cached is not None]
    out = [f"fitting {', '.join(p.name for p in fits)} on {where}"] if fits else []
    if loads:
        out.append(f"{', '.join(p.name for p in loads)}: fitted before on "
                   f"{'the same samples' if fits else where}; loaded from the cache "
                   f"({loads[0].cached.parent}), not fitted again")
    twice = [p for p in fits if p.rounds == 2]
    if twice:
        v = twice[0].validation
        part = f"the first {100 * (1 - v):g} % of those frames"
        if frames is not None:
            cut = round((1.0 - v) * frames)
            part += f" (0–{cut - 1}), its forecasts on the rest ({cut}–{frames - 1})"
        else:
            part += ", its forecasts on the rest"
        out.append(f"each network is fitted twice: a validation round on {part} give the "
                   "out-of-sample error the combination starts from; then the final round on "
                   "all of them")
    total = sum(p.estimate_s for p in fits if p.estimate_s is not None)
    if fits:
        out.append(f"about {duration(total)} of fitting (each network predictor timed "
                   "from a few epochs of one network): " + "; ".join(
                       f"{p.name} {_seconds(p)}" + (f" ({p.networks} networks × {p.rounds} "
                                                     "rounds)" if p.networks else "")
                       for p in fits))
    if omitted:
        names = ", ".join(p.name for p in omitted)
        out.append(f"left out of the default set: {names} (about "
                   f"{' and '.join(_seconds(p) for p in omitted)} of fitting here); add them "
                   f"with --predictors {','.join([*every, *(p.name for p in omitted)])}")
    return out
