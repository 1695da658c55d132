"""Every predictor on a user's recordings, open loop, each at the recording's own rate.

Each predictor is built with ``make_predictor(name, dt=Δ)``, Δ = 1/rate the file's median
sample period, and sees every raw sample once, in order (a missing sample, NaN or a gap in
the timestamps, is fed as missing). After every update n past the warm-up it forecasts
ẑ_{n+1|n} … ẑ_{n+K|n}; the error at lead k is e_k(n) = ‖ẑ_{n+k|n} − z_{n+k}‖, scored where
z_{n+k} was measured. Reported per lead: RMS and max of e_k [mm], the ratio of the RMS to
the hold forecast's (ẑ_{n+k|n} = z_n) at the same lead, and the predictor's events over the
scored part.

Rules
-----
Warm-up
    The first max(10 s, 25 % of the recording) are excluded (``warmup`` overrides it): the
    predictors converge there, as the closed loop's settling time lets them.
Lead the closed loop needs
    K_loop = ⌈(Δ + λ + N·Ts) / Δ⌉ samples: the forecast made from a sample serves the loop
    until the next sample arrives, one period Δ later plus the delivery latency λ, and must
    reach the MPC's horizon N·Ts (25 ms) beyond that. At 25 Hz: ⌈(40 + 0 + 25)/40⌉ = 2.
Events
    ``rejected``: samples the predictor's own gate refused (``innovation_rejected``, the
    Fourier EKFs); ``repaired``: forecasts its divergence guard repaired (``forecast_clamped``,
    ``forecast_nonfinite``) and samples it retracted (``retracted``); ``missing``: samples
    fed as missing. The closed loop's outlier gate is not part of the open loop.
Several points
    A file of several tracked points (:mod:`rhmpc.sim.recordings.points`) is scored point by point;
    with ``mean`` the study adds a row per predictor and lead whose errors are the means over
    the points. With a point of interest (``poi``), that point is scored and every predictor
    that reads the other points (``multi_point``) is fed them, sample by sample: at update n
    the samples ≤ n of every point.
The literature's protocol (``split`` = (TRAIN, END))
    The predictors fitted before the run (``rhmpc.predictors.LEARNED``) are fitted on the samples
    before TRAIN (all points, the POI first), or on other recordings (``train``); every other
    predictor runs causally from the first sample; the forecasts issued in [TRAIN, END) are
    scored, at leads 1 … L. Without ``split`` the warm-up rule holds, and the fitted
    predictors take part only when there are training recordings.
Families
    Each row names its predictor's family (``rhmpc.predictors.family``): ``baseline``,
    ``adaptive``, ``multi-point``, ``learned`` or ``combination``. The combination weighs the
    other scored predictors that are not baselines, per lead, by their recent errors; in the
    literature's protocol it scores nothing before TRAIN, where the fitted members' misses are
    not forecast errors, and starts from their validation errors.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rhmpc.experiment.fit_plan import describe, fit_all, plan_fits
from rhmpc.openloop.tracks import Track, twelve_digits
from rhmpc.predictors import LEARNED, family, make_predictor, needs_torch, predictor_names
from rhmpc.predictors.combination import Combination, CombinationSettings
from rhmpc.predictors.registry import default_predictors, torch_available
from rhmpc.sim.recordings.points import on_grid

#: Leads 1 … DEFAULT_LEADS are scored [samples].
DEFAULT_LEADS = 5
#: Warm-up: the longer of this many seconds [s] …
WARMUP_SECONDS = 10.0
#: … and this fraction of the recording [-].
WARMUP_FRACTION = 0.25
#: Counter names of the predictors summed into ``rejected`` and ``repaired``.
REJECTED = ("innovation_rejected", "outliers_rejected")
REPAIRED = ("forecast_clamped", "forecast_nonfinite", "retracted")


@dataclass(frozen=True)
class OpenLoopSettings:
    """How the open-loop scoring runs.

    Attributes
    ----------
    predictors : tuple[str, ...]
        Predictor names (``rhmpc.predictors.predictor_names()``, not ``exact``); empty = the
        defaults (:func:`default_predictors`).
    leads : int
        L: leads 1 … L are scored, and the closed loop's lead K_loop [samples].
    warmup : float | None
        Seconds excluded from the start of each recording [s]; ``None`` = the longer of
        WARMUP_SECONDS and WARMUP_FRACTION of the recording. Not with ``split``.
    latency : float
        λ, the delivery latency of the samples to the controller [s] (0: each sample is
        available at its timestamp).
    horizon : float
        N·Ts, the MPC's reach beyond the newest tick [s] (50 × 0.5 ms).
    split : tuple[int, int] | None
        (TRAIN, END) [samples, from 0, on the recording's grid]: the fitted predictors are
        fitted on the samples before TRAIN (or on the training recordings), the forecasts
        issued in [TRAIN, END) are scored. ``None``: the warm-up rule.
    seed : int
        Seed of the fitted predictors' random draws (their ``seed`` setting).
    """

    predictors: tuple[str, ...] = ()
    leads: int = DEFAULT_LEADS
    warmup: float | None = None
    latency: float = 0.0
    horizon: float = 0.025
    split: tuple[int, int] | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        bad = [n for n in self.predictors if n not in predictor_names() or n == "exact"]
        if bad:
            valid = ", ".join(default_predictors(fitted=True))
            raise ValueError(f"unknown predictor(s) {', '.join(bad)}; valid: {valid}")
        if isinstance(self.leads, bool) or not isinstance(self.leads, int) or self.leads < 1:
            raise ValueError(f"leads must be an integer >= 1, got {self.leads!r}")
        if self.warmup is not None and not (math.isfinite(self.warmup) and self.warmup >= 0):
            raise ValueError(f"the warm-up must be >= 0 [s], got {self.warmup!r}")
        if not (math.isfinite(self.latency) and self.latency >= 0):
            raise ValueError(f"the latency must be >= 0 [s], got {self.latency!r}")
        if not (math.isfinite(self.horizon) and self.horizon > 0):
            raise ValueError(f"the horizon must be > 0 [s], got {self.horizon!r}")
        if self.split is not None:
            train, end = self.split
            if not 0 < train < end:
                raise ValueError(f"the split TRAIN:END must have 0 < TRAIN < END [samples], "
                                 f"got {train}:{end}")
            if self.warmup is not None:
                raise ValueError("a split scores from TRAIN: it takes no warm-up")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"the seed must be an integer >= 0, got {self.seed!r}")

    def names(self, fitted: bool = False) -> tuple[str, ...]:
        """The predictors to score; ``fitted``: whether there is something to fit on."""
        if not self.predictors:
            return default_predictors(fitted)
        fit_needed = [n for n in self.predictors if n in LEARNED]
        if fit_needed and not fitted:
            raise ValueError(f"{', '.join(fit_needed)} must be fitted before the run: give a "
                             "split TRAIN:END or training recordings")
        return self.predictors


def loop_lead(period: float, latency: float, horizon: float) -> int:
    """K_loop = ⌈(Δ + λ + N·Ts)/Δ⌉ [samples] (module docstring), robust to rounding."""
    return max(1, math.ceil((period + latency + horizon) / period - 1e-9))


def warmup_seconds(duration: float, warmup: float | None) -> float:
    """The warm-up [s]: ``warmup``, or max(WARMUP_SECONDS, WARMUP_FRACTION · duration)."""
    if warmup is not None:
        return float(warmup)
    return max(WARMUP_SECONDS, WARMUP_FRACTION * duration)


def forecast_errors(predictor, z: np.ndarray, period: float, first: int, depth: int,
                    others: np.ndarray | None = None, end: int | None = None
                    ) -> tuple[np.ndarray, dict[str, int]]:
    """e_k(n) [m] for origins n in [``first``, ``end``) and leads k = 1 … ``depth``, and the
    events.

    ``predictor``: a name (built with ``make_predictor(name, dt=period)``) or a predictor;
    ``others`` (n, P − 1, d): the other points, fed to a ``multi_point`` one. Returns an array
    (len(z), depth) — NaN where not scored (outside [first, end), past the end, or a missing
    target) — and the predictor's counters accumulated from ``first`` on (``update_us``: its
    mean update-and-forecast time over the scored origins [µs]).
    """
    if isinstance(predictor, str):
        predictor = make_predictor(predictor, dt=period)
    n_total = z.shape[0]
    end = n_total if end is None else min(end, n_total)
    forecasts = np.full((n_total, depth, z.shape[1]), np.nan)
    before: dict[str, int] = {}
    spent, timed = 0.0, 0
    for n in range(end):
        tic = time.perf_counter()
        predictor.update(z[n], None if others is None else others[n])
        if n < first:
            continue
        if n == first:
            before = dict(predictor.counts)
        try:
            forecasts[n] = predictor.predict(depth)
        except RuntimeError:  # no valid sample yet
            continue
        spent += time.perf_counter() - tic
        timed += 1
    errors = np.full((n_total, depth), np.nan)
    for k in range(1, depth + 1):
        miss = forecasts[: n_total - k, k - 1] - z[k:]
        errors[: n_total - k, k - 1] = np.linalg.norm(miss, axis=1)
    counts = {key: int(v - before.get(key, 0)) for key, v in predictor.counts.items()}
    counts = {k: v for k, v in counts.items() if v}
    if timed:
        counts["update_us"] = round(1e6 * spent / timed)
    return errors, counts


def _rows(track: Track, name: str, errors: np.ndarray, counts: dict, leads: list[int],
          k_loop: int) -> list[dict]:
    """One result row per lead of predictor ``name`` on ``track``."""
    period = track.period
    counts = dict(counts)
    fit_s, update_us = counts.pop("fit_s", None), counts.pop("update_us", None)
    out = []
    for k in leads:
        e = errors[:, k - 1]
        e = 1e3 * e[np.isfinite(e)]
        out.append({
            "source": track.label, "predictor": name, "family": family(name),
            "lead_samples": k, "lead_s": twelve_digits(k * period),
            "rms_error_mm": float(np.sqrt(np.mean(e**2))) if e.size else None,
            "max_error_mm": float(np.max(e)) if e.size else None,
            "scored": int(e.size), "loop_lead": k == k_loop,
            "rejected": sum(counts.get(c, 0) for c in REJECTED),
            "repaired": sum(counts.get(c, 0) for c in REPAIRED),
            "missing": counts.get("missing", 0), "counts": counts,
            "fit_s": fit_s, "update_us": update_us,
        })
    return out


def _origins(track: Track, t: np.ndarray, settings: OpenLoopSettings, last_lead: int
             ) -> tuple[int, int, float]:
    """(first, end, warm-up [s]): the origins scored, [first, end) on the grid ``t``."""
    duration = float(track.t[-1] - track.t[0])
    if settings.split is not None:
        first, end = settings.split
        if first + 1 >= t.size:
            raise ValueError(f"{track.label}: holds {t.size} samples; the split starts "
                             f"scoring at sample {first}")
        return first, min(end, t.size), float(t[first] - t[0])
    warmup = warmup_seconds(duration, settings.warmup)
    first = int(np.searchsorted(t, t[0] + warmup - 1e-9))
    if first + last_lead >= t.size:
        raise ValueError(f"{track.label}: lasts {duration:.2f} s; a warm-up of {warmup:.2f} s "
                         f"and a lead of {last_lead} samples leave nothing to score "
                         "(shorten it with --warmup)")
    return first, t.size, warmup


def score_track(track: Track, settings: OpenLoopSettings,
                progress: Callable[[str], None] | None = None,
                train: list[np.ndarray] | None = None,
                save: Path | None = None) -> tuple[dict, list[dict]]:
    """The source's description and the result rows of every predictor on ``track``.

    ``train``: the recordings to fit the fitted predictors on
    (:func:`rhmpc.sim.recordings.training_series`); default, with a split, the track's samples
    before TRAIN. ``save``: a folder to write the fitted models to (their ``save``).

    Raises
    ------
    ValueError
        The warm-up leaves nothing to score (the message names the lengths), a split beyond
        the recording, or fitted predictors and nothing to fit them on.
    """
    period = track.period
    wide = track.points().reshape(track.t.size, -1)
    t, wide = on_grid(track.t, wide, period)
    grid = wide.reshape(wide.shape[0], -1, track.z.shape[1])
    z, others = grid[:, 0], (grid[:, 1:] if grid.shape[1] > 1 else None)
    k_loop = loop_lead(period, settings.latency, settings.horizon)
    leads = sorted({*range(1, settings.leads + 1), k_loop})
    first, end, warmup = _origins(track, t, settings, leads[-1])
    where = "the training recordings"
    if train is None and settings.split is not None:
        train = [grid[:first]]
        where = (f"frames 0–{first - 1} of {track.label} (the frames before TRAIN = {first}; "
                 f"the forecasts issued at frames {first}–{end - 1} are scored)")
    names = settings.names(fitted=train is not None)
    fitted = _fit(names, settings, period, train, leads[-1], progress, save, track.label,
                  where) if train else {}
    rows: list[dict] = []
    for name in names:
        if progress is not None:
            progress(f"{name} on {track.label}")
        if name == "combination":
            predictor = _combination(names, fitted, period, leads[-1],
                                     first if settings.split else 0)
        elif name in fitted:
            predictor = copy.deepcopy(fitted[name][0])
        else:
            predictor = make_predictor(name, dt=period)
        errors, counts = forecast_errors(predictor, z, period, first, leads[-1], others, end)
        if name in fitted:
            counts["fit_s"] = round(fitted[name][1], 2)
        rows += _rows(track, name, errors, counts, leads, k_loop)
    _ratios(rows)
    source = {
        "label": track.label, "file": track.file, "point": track.point,
        "rate_hz": twelve_digits(1.0 / period), "period_s": period,
        "duration_s": float(track.t[-1] - track.t[0]),
        "samples": int(track.t.size), "missing": int(np.sum(~np.isfinite(z).all(axis=1))),
        "warmup_s": warmup, "loop_lead_samples": k_loop,
        "loop_lead_s": twelve_digits(k_loop * period),
        "gap_samples": int(t.size - track.t.size),
        "regular": bool(np.allclose(np.diff(t), period, rtol=0.05)),
        "points": grid.shape[1], "scored_from": first, "scored_to": end,
    }
    for row in rows:
        row["rate_hz"] = source["rate_hz"]
    return source, rows


def left_out(names: Sequence[str]) -> list[str]:
    """The fitted predictors that could run here (PyTorch installed for a network) but are not
    among ``names``: those the default set leaves out."""
    return [n for n in LEARNED if n not in names and (not needs_torch(n) or torch_available())]


def _fit(names, settings: OpenLoopSettings, period: float, series: list[np.ndarray],
         leads: int, progress, save: Path | None, label: str, where: str) -> dict:
    """name → (fitted predictor, seconds) of the fitted predictors among ``names``, after the
    plan is said (:func:`rhmpc.experiment.fit_plan.describe`): what, on which frames, why in two
    rounds, how long, and which fitted predictors the default set leaves out."""
    plans = plan_fits(names, period, series, leads, settings.seed)
    if not plans:
        return {}
    if progress is not None:
        spare = [] if settings.predictors else left_out(names)
        omitted = plan_fits(spare, period, series, leads, settings.seed)
        frames = series[0].shape[0] if len(series) == 1 else None
        for line in describe(plans, where, frames, omitted, names):
            progress(line)
    return fit_all(plans, period, series, leads, settings.seed, progress, save, label)


def _combination(names, fitted: dict, period: float, leads: int, score_from: int
                 ) -> Combination:
    """The combination of the other scored predictors that are not baselines (copies of the
    fitted ones)."""
    members = [n for n in names if family(n) not in ("baseline", "combination")]
    if not members:
        raise ValueError("the combination needs a scored predictor that is not a baseline")
    instances = [copy.deepcopy(fitted[n][0]) if n in fitted else make_predictor(n, dt=period)
                 for n in members]
    s = CombinationSettings(members=tuple(members), leads=leads, score_from=score_from)
    return Combination(period, s, instances)


def _ratios(rows: list[dict]) -> None:
    """``ratio_to_hold``: each row's RMS over hold's at the same source and lead."""
    hold = {(r["source"], r["lead_samples"]): r["rms_error_mm"] for r in rows
            if r["predictor"] == "hold"}
    for r in rows:
        ref = hold.get((r["source"], r["lead_samples"]))
        ok = ref and r["rms_error_mm"] is not None
        r["ratio_to_hold"] = r["rms_error_mm"] / ref if ok else None


def mean_rows(label: str, rows: Sequence[dict]) -> list[dict]:
    """Rows of ``label`` whose errors are the means over the sources of ``rows`` per predictor
    and lead (events summed)."""
    groups: dict[tuple[str, int], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["predictor"], r["lead_samples"]), []).append(r)
    out = []
    for (name, k), group in groups.items():
        rms = [g["rms_error_mm"] for g in group if g["rms_error_mm"] is not None]
        mx = [g["max_error_mm"] for g in group if g["max_error_mm"] is not None]
        out.append({
            "source": label, "predictor": name, "family": family(name), "lead_samples": k,
            "lead_s": float(np.mean([g["lead_s"] for g in group])),
            "rms_error_mm": float(np.mean(rms)) if rms else None,
            "max_error_mm": float(np.mean(mx)) if mx else None,
            "scored": sum(g["scored"] for g in group),
            "loop_lead": all(g["loop_lead"] for g in group),
            **{key: sum(g[key] for g in group) for key in ("rejected", "repaired", "missing")},
            "points": len(group), "rate_hz": group[0]["rate_hz"],
        })
    _ratios(out)
    return out


def run_open_loop(tracks: Sequence[Track | list[Track]], settings: OpenLoopSettings,
                  progress: Callable[[str], None] | None = None,
                  train: Callable[[float], list[np.ndarray]] | None = None,
                  save: Path | None = None) -> dict:
    """Score every predictor on every track; a list of tracks (the points of one file) also
    gets its ``mean`` rows, labelled ``FILE:mean``.

    ``train(period)``: the recordings to fit the fitted predictors on, on the grid of
    ``period`` [s] (e.g. :func:`rhmpc.sim.recordings.training_series`); default, with a split, each
    track's samples before TRAIN. ``save``: a folder to write the fitted models to.

    Returns
    -------
    dict
        ``rate_hz`` and ``warmup_s`` (shared by every source, else ``None``), ``sources``
        (one description each), ``results`` (one row per source × predictor × lead:
        ``predictor``, ``family``, ``lead_samples``, ``lead_s``, ``rms_error_mm``,
        ``max_error_mm``, ``ratio_to_hold``, ``rejected``, ``repaired``, ``missing``,
        ``loop_lead``, ``fit_s``, ``update_us`` …), the protocol (``protocol``: ``online`` or
        ``split``, ``split``) and the rules (``warmup_rule``, ``loop_lead_rule``).
    """
    sources, results, names = [], [], []
    if progress is not None and not settings.predictors and not torch_available() and (
            train is not None or settings.split is not None):
        left = [n for n in LEARNED if needs_torch(n)]
        progress(f"{', '.join(left)} left out: they need PyTorch "
                 '(pip install "rhmpc[learned]")')
    for item in tracks:
        group = item if isinstance(item, list) else [item]
        rows_of_group = []
        for track in group:
            series = None if train is None else train(track.period)
            source, rows = score_track(track, settings, progress, series, save)
            sources.append(source)
            rows_of_group += rows
        results += rows_of_group
        if isinstance(item, list) and len(group) > 1:
            results += mean_rows(f"{group[0].label.rsplit(':', 1)[0]}:mean", rows_of_group)
    names = list(dict.fromkeys(r["predictor"] for r in results))
    rates = {round(s["rate_hz"], 9) for s in sources}
    warmups = {round(s["warmup_s"], 9) for s in sources}
    return {
        "rate_hz": sources[0]["rate_hz"] if len(rates) == 1 else None,
        "warmup_s": sources[0]["warmup_s"] if len(warmups) == 1 else None,
        "latency_s": settings.latency, "horizon_s": settings.horizon,
        "leads": settings.leads, "predictors": names,
        "protocol": "online" if settings.split is None else "split",
        "split": None if settings.split is None else list(settings.split),
        "fitted_on": ("the training recordings" if train is not None else
                      f"frames 0–{settings.split[0] - 1}, the frames before "
                      f"{settings.split[0]}" if settings.split is not None else None),
        "seed": settings.seed,
        "warmup_rule": "split" if settings.split is not None else "given"
        if settings.warmup is not None else
        f"max({WARMUP_SECONDS:g} s, {100 * WARMUP_FRACTION:g} % of the recording)",
        "loop_lead_rule": "ceil((period + latency + horizon) / period)",
        "sources": sources, "results": results,
    }
