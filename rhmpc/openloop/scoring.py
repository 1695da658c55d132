"""Scoring one track open loop: each predictor fed every sample once, its forecasts' errors
per lead (the rules: :mod:`rhmpc.openloop.recordings`; the plan: :mod:`rhmpc.openloop.plan`)."""

from __future__ import annotations

import copy
import time
from collections.abc import Callable, Sequence

import numpy as np

from rhmpc.experiment.fit_plan import duration, step_seconds
from rhmpc.openloop.plan import (
    REJECTED,
    REPAIRED,
    TrackPlan,
    scored_members,
)
from rhmpc.openloop.tracks import Track, twelve_digits
from rhmpc.predictors import family, make_predictor
from rhmpc.predictors.combination import Combination, CombinationSettings

__all__ = ["forecast_errors", "mean_rows", "ratios", "result_rows", "score"]


def score(plan: TrackPlan, fitted: dict, progress: Callable[[str], None] | None = None
          ) -> tuple[dict, list[dict]]:
    """The source's description and the result rows of every predictor of ``plan``, the
    fitted ones copies of ``fitted`` (name → (predictor, seconds, cached model or None)); each
    predictor's turn said with its estimate."""
    track, period, grid = plan.track, plan.track.period, plan.grid
    z, others = grid[:, 0], (grid[:, 1:] if grid.shape[1] > 1 else None)
    depth, rows = plan.leads[-1], []
    for name in plan.names:
        if name == "combination":
            predictor = _combination(plan.names, fitted, period, depth,
                                     plan.first if plan.settings.split else 0)
        elif name in fitted:
            predictor = copy.deepcopy(fitted[name][0])
        else:
            predictor = make_predictor(name, dt=period)
        if progress is not None:
            step = plan.steps.get(name)
            if step is None:  # a fitted predictor that was not probed: timed now
                step = step_seconds(copy.deepcopy(predictor), grid, depth)
            progress(f"{name} on {track.label} (about {duration(plan.end * step)})")
        errors, counts = forecast_errors(predictor, z, period, plan.first, depth, others,
                                         plan.end)
        if name in fitted:
            counts["fit_s"] = round(fitted[name][1], 2)
            counts["model_from"] = "fitted" if fitted[name][2] is None else "cache"
        rows += result_rows(track, name, errors, counts, plan.leads, plan.k_loop)
    ratios(rows)
    t = plan.t
    source = {
        "label": track.label, "file": track.file, "point": track.point,
        "rate_hz": twelve_digits(1.0 / period), "period_s": period,
        "duration_s": float(track.t[-1] - track.t[0]),
        "samples": int(track.t.size), "missing": int(np.sum(~np.isfinite(z).all(axis=1))),
        "warmup_s": plan.warmup, "loop_lead_samples": plan.k_loop,
        "loop_lead_s": twelve_digits(plan.k_loop * period),
        "gap_samples": int(t.size - track.t.size),
        "regular": bool(np.allclose(np.diff(t), period, rtol=0.05)),
        "points": grid.shape[1], "scored_from": plan.first, "scored_to": plan.end,
    }
    for row in rows:
        row["rate_hz"] = source["rate_hz"]
    return source, rows


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


def result_rows(track: Track, name: str, errors: np.ndarray, counts: dict, leads: list[int],
          k_loop: int) -> list[dict]:
    """One result row per lead of predictor ``name`` on ``track``."""
    period = track.period
    counts = dict(counts)
    fit_s, update_us = counts.pop("fit_s", None), counts.pop("update_us", None)
    model_from = counts.pop("model_from", None)
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
            "fit_s": fit_s, "model_from": model_from, "update_us": update_us,
        })
    return out


def _combination(names, fitted: dict, period: float, leads: int, score_from: int
                 ) -> Combination:
    """The combination of the other scored predictors that are not baselines (copies of the
    fitted ones)."""
    members = scored_members(names)
    if not members:
        raise ValueError("the combination needs a scored predictor that is not a baseline")
    instances = [copy.deepcopy(fitted[n][0]) if n in fitted else make_predictor(n, dt=period)
                 for n in members]
    s = CombinationSettings(members=tuple(members), leads=leads, score_from=score_from)
    return Combination(period, s, instances)


def ratios(rows: list[dict]) -> None:
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
    ratios(out)
    return out
