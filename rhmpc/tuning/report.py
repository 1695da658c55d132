"""Ranking a sweep's results: the points' summaries, the table and the best settings as TOML
(the objective's figure: :mod:`rhmpc.tuning.figure`)."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rhmpc.experiment import RunConfig
from rhmpc.tuning.objective import Objective, metric_value, parse_objective

#: Metrics shown in every table (document units), after the objective's own.
TABLE_METRICS = ("rms_error_mm", "max_error_mm", "rms_effort_mNm")

#: Ranking classes, best first.
STATUS_ORDER = ("ok", "incomplete", "infeasible", "failed")


@dataclass
class PointSummary:
    """A point's evaluations summarised under an objective.

    Attributes
    ----------
    point : str
        Point key (hash of its settings without scenario and seed).
    parameters : dict
        The varied settings (dotted keys).
    base : bool
        The spec's base settings.
    n_ok, n_failed : int
        Evaluations finished, by status.
    n_expected : int | None
        Evaluations per point in the spec that produced the records.
    score_mean, score_std : float
        Mean and standard deviation (ddof = 1; 0 for one evaluation) of the objective over the
        point's successful evaluations (scenarios × seeds).
    means, stds : dict[str, float]
        The same for each metric in :data:`TABLE_METRICS` and the objective's metrics.
    status : str
        ``"ok"``, ``"incomplete"`` (evaluations missing), ``"infeasible"`` (a constraint is
        violated) or ``"failed"`` (an evaluation failed, or none succeeded).
    errors : list[str]
        Errors of the failed evaluations.
    records : list[dict]
        The successful records, ordered by their index within the point.
    """

    point: str
    parameters: dict
    base: bool = False
    n_ok: int = 0
    n_failed: int = 0
    n_expected: int | None = None
    score_mean: float = math.nan
    score_std: float = math.nan
    means: dict[str, float] = field(default_factory=dict)
    stds: dict[str, float] = field(default_factory=dict)
    status: str = "ok"
    errors: list[str] = field(default_factory=list)
    records: list[dict] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "point": self.point, "parameters": self.parameters, "base": self.base,
            "status": self.status, "score_mean": _json_float(self.score_mean),
            "score_std": _json_float(self.score_std), "n_ok": self.n_ok,
            "n_failed": self.n_failed, "n_expected": self.n_expected,
            "means": {k: _json_float(v) for k, v in self.means.items()},
            "stds": {k: _json_float(v) for k, v in self.stds.items()},
            "errors": self.errors,
            "evaluations": [{"scenario": r.get("scenario"), "seed": r.get("seed"),
                             "key": r.get("key")} for r in self.records],
        }


def _json_float(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def objective_of(records: Sequence[dict]) -> Objective:
    """The objective stored with the newest record that has one (default: RMS error)."""
    for r in reversed(records):
        if isinstance(r.get("objective"), dict):
            return parse_objective(r["objective"], where="results")
    return Objective()


def _mean_std(values: Sequence[float]) -> tuple[float, float]:
    a = np.asarray([v for v in values if math.isfinite(v)], dtype=float)
    if a.size == 0:
        return math.nan, math.nan
    return float(a.mean()), float(a.std(ddof=1)) if a.size > 1 else 0.0


def summarize(records: Iterable[dict], objective: Objective,
              points: Sequence[str] | None = None) -> list[PointSummary]:
    """Group the latest record of each evaluation by point and rank the points.

    Parameters
    ----------
    records : iterable of dict
        Results lines (later lines of the same key replace earlier ones; ``ok`` wins).
    objective : Objective
        How to score an evaluation and which constraints apply.
    points : sequence of str, optional
        Only these point keys (e.g. the points of one spec).

    Returns
    -------
    list[PointSummary]
        Best first: by status class (:data:`STATUS_ORDER`), then by mean objective.
    """
    latest: dict[str, dict] = {}
    for r in records:
        prev = latest.get(r["key"])
        if prev is None or r.get("status") == "ok" or prev.get("status") != "ok":
            latest[r["key"]] = r
    wanted = set(points) if points is not None else None
    groups: dict[str, list[dict]] = {}
    for r in latest.values():
        if wanted is None or r.get("point") in wanted:
            groups.setdefault(r.get("point", r["key"]), []).append(r)
    names = tuple(dict.fromkeys([*objective.metrics, *TABLE_METRICS]))
    out = []
    for point, rs in groups.items():
        rs.sort(key=lambda r: r.get("index", 0))
        ok = [r for r in rs if r.get("status") == "ok"]
        bad = [r for r in rs if r.get("status") != "ok"]
        s = PointSummary(point, rs[0].get("parameters", {}), any(r.get("base") for r in rs),
                         len(ok), len(bad), rs[0].get("evaluations_per_point"),
                         errors=[str(r.get("error", "failed")) for r in bad], records=ok)
        s.score_mean, s.score_std = _mean_std([objective.score(r["metrics"]) for r in ok])
        for name in names:
            s.means[name], s.stds[name] = _mean_std([metric_value(r["metrics"], name)
                                                     for r in ok])
        if bad or not ok or not math.isfinite(s.score_mean):
            s.status = "failed"
        elif not objective.feasible(s.means):
            s.status = "infeasible"
        elif s.n_expected is not None and s.n_ok < s.n_expected:
            s.status = "incomplete"
        out.append(s)
    out.sort(key=lambda s: (STATUS_ORDER.index(s.status),
                            s.score_mean if math.isfinite(s.score_mean) else math.inf))
    return out


def format_value(value: Any) -> str:
    """A parameter value for a table cell."""
    if isinstance(value, bool) or value is None:
        return str(value).lower()
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, list):
        text = json.dumps(value, separators=(",", ":"))
        return text if len(text) <= 24 else text[:21] + "..."
    return str(value)


def parameter_keys(summaries: Sequence[PointSummary]) -> list[str]:
    return list(dict.fromkeys(k for s in summaries for k in s.parameters))


def format_table(summaries: Sequence[PointSummary], objective: Objective,
                 top: int | None = None) -> str:
    """The ranked table: objective mean ± spread, evaluations, metric means, parameters."""
    keys = parameter_keys(summaries)
    names = tuple(dict.fromkeys([*TABLE_METRICS, *objective.metrics[1:]]))
    header = ["rank", "objective (mean ± sd)", "n", *names, *keys, "note"]
    rows = []
    shown = summaries if top is None else summaries[:top]
    for i, s in enumerate(shown, 1):
        n = f"{s.n_ok}/{s.n_expected}" if s.n_expected else str(s.n_ok)
        note = [] if s.status == "ok" else [s.status]
        if s.base:
            note.insert(0, "base")
        rows.append([
            str(i),
            f"{s.score_mean:.4g} ± {s.score_std:.2g}" if math.isfinite(s.score_mean) else "-",
            n,
            *(f"{s.means[m]:.4g}" if math.isfinite(s.means.get(m, math.nan)) else "-"
              for m in names),
            *(format_value(s.parameters[k]) if k in s.parameters else "-" for k in keys),
            ", ".join(note),
        ])
    right = [j in (0, 2) or 3 <= j < 3 + len(names) for j in range(len(header))]
    lines = align([header, *rows], right)
    if top is not None and len(summaries) > top:
        lines.append(f"... {len(summaries) - top} more points (--top)")
    return "\n".join(lines)


def align(rows: Sequence[Sequence[str]], right: Sequence[bool] | None = None) -> list[str]:
    """Rows of cells as lines of aligned columns (``right[j]``: right-align column ``j``)."""
    widths = [max(len(r[j]) for r in rows) for j in range(len(rows[0]))]
    right = right or [False] * len(widths)
    return ["  ".join(c.rjust(w) if rj else c.ljust(w)
                      for c, w, rj in zip(r, widths, right, strict=True)).rstrip() for r in rows]


def best(summaries: Sequence[PointSummary]) -> PointSummary | None:
    """The best point that is complete and feasible (else the best incomplete one)."""
    for status in ("ok", "incomplete"):
        for s in summaries:
            if s.status == status:
                return s
    return None


def best_config(summary: PointSummary) -> RunConfig:
    """The run settings of ``summary``'s first evaluation (its first scenario and seed)."""
    return RunConfig.from_dict(summary.records[0]["settings"], where="best settings")


def best_toml(summary: PointSummary, objective: Objective, results: str = "") -> str:
    """``summary``'s settings as a ``simulate --config`` file, with a comment header."""
    import tomli_w

    config = best_config(summary)
    evals = ", ".join(f"{r.get('scenario')} seed {r.get('seed')}" for r in summary.records)
    params = ", ".join(f"{k} = {format_value(v)}" for k, v in summary.parameters.items())
    header = [
        f"# rhmpc tune: best settings{f' from {results}' if results else ''}",
        f"# objective: {objective.describe()}",
        f"#   = {summary.score_mean:.6g} ± {summary.score_std:.3g} over {summary.n_ok} "
        f"evaluation(s): {evals}",
        f"# parameters: {params or '(the base settings)'}",
        "# use: rhmpc simulate --config THIS_FILE.toml",
        "",
    ]
    return "\n".join(header) + tomli_w.dumps(config.to_dict())
