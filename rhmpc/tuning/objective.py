"""What a sweep minimises: the objective, its penalties and constraints, metric look-up, and the
spec's ``objective`` table read into them (:func:`parse_objective`).

The objective of one evaluation is ``metric + Σ weight·max(0, penalty_metric − limit)``; a point's
score is its mean over the point's evaluations, and points whose means break a constraint rank
after every feasible point. Metric names are keys of the run document, dotted for nested entries
(``"tick_us.p99"``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from rhmpc.errors import UsageError

__all__ = ["Constraint", "Objective", "Penalty", "check_keys", "check_objective_metrics",
           "is_number", "metric_names", "metric_value", "parse_objective"]


@dataclass(frozen=True)
class Penalty:
    """``weight · max(0, metric − limit)`` added to an evaluation's objective.

    Attributes
    ----------
    metric : str
        Document key (dotted for nested entries), in its document unit (mm, mN·m, µs).
    weight : float
        Objective units per metric unit [-].
    limit : float
        Value below which the penalty is zero, in the metric's unit.
    """

    metric: str
    weight: float
    limit: float = 0.0


@dataclass(frozen=True)
class Constraint:
    """Bounds on the mean of ``metric`` over a point's evaluations (infeasible: ranked last).

    Attributes
    ----------
    metric : str
        Document key (dotted for nested entries).
    max, min : float | None
        Inclusive bounds in the metric's unit; ``None`` = unbounded.
    """

    metric: str
    max: float | None = None
    min: float | None = None


@dataclass(frozen=True)
class Objective:
    """What a sweep minimises: the mean over a point's evaluations of ``metric`` + penalties.

    Attributes
    ----------
    metric : str
        Document key to minimise (e.g. ``"rms_error_mm"``).
    penalties : tuple[Penalty, ...]
        Soft terms added per evaluation.
    constraints : tuple[Constraint, ...]
        Hard bounds on point means.
    """

    metric: str = "rms_error_mm"
    penalties: tuple[Penalty, ...] = ()
    constraints: tuple[Constraint, ...] = ()

    def score(self, metrics: dict) -> float:
        """The objective of one evaluation (NaN when a metric is missing)."""
        value = metric_value(metrics, self.metric)
        for p in self.penalties:
            value += p.weight * max(0.0, metric_value(metrics, p.metric) - p.limit)
        return value

    def feasible(self, means: dict[str, float]) -> bool:
        """Whether the point means satisfy every constraint."""
        for c in self.constraints:
            v = means.get(c.metric, math.nan)
            if not math.isfinite(v):
                return False
            if c.max is not None and v > c.max:
                return False
            if c.min is not None and v < c.min:
                return False
        return True

    @property
    def metrics(self) -> tuple[str, ...]:
        """Every metric the objective reads, main metric first."""
        names = [self.metric, *(p.metric for p in self.penalties),
                 *(c.metric for c in self.constraints)]
        return tuple(dict.fromkeys(names))

    def describe(self) -> str:
        text = f"mean {self.metric}"
        for p in self.penalties:
            text += f" + {p.weight:g}·max(0, {p.metric} − {p.limit:g})"
        for c in self.constraints:
            bounds = []
            if c.min is not None:
                bounds.append(f"≥ {c.min:g}")
            if c.max is not None:
                bounds.append(f"≤ {c.max:g}")
            text += f", subject to mean {c.metric} {' and '.join(bounds)}"
        return text

    def to_dict(self) -> dict:
        return {
            "metric": self.metric,
            "penalty": [dataclasses.asdict(p) for p in self.penalties],
            "constraint": [{k: v for k, v in dataclasses.asdict(c).items() if v is not None}
                           for c in self.constraints],
        }


def metric_value(metrics: dict, name: str) -> float:
    """``metrics[name]``; dotted names reach into nested entries (``"tick_us.p99"``,
    ``"rms_error_axis_mm.2"``). NaN if absent or not a number."""
    value: Any = metrics
    for part in name.split("."):
        if isinstance(value, dict) and part in value:
            value = value[part]
        elif isinstance(value, list) and part.isdigit() and int(part) < len(value):
            value = value[int(part)]
        else:
            return math.nan
    if isinstance(value, bool):
        return float(value)
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def metric_names(metrics: dict, prefix: str = "") -> list[str]:
    """Every name :func:`metric_value` can read from ``metrics`` (dotted for nested ones)."""
    out = []
    for key, value in metrics.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out.extend(metric_names(value, prefix=f"{name}."))
        elif isinstance(value, list):
            out.extend(f"{name}.{i}" for i in range(len(value)))
        else:
            out.append(name)
    return out


def check_objective_metrics(objective: Objective, metrics: dict) -> None:
    """Raise ``UsageError`` if the objective reads a metric the run documents do not have."""
    names = metric_names(metrics)
    for name in objective.metrics:
        if name not in names:
            raise UsageError(f"objective: metric {name!r} is not in the results; available: "
                             f"{', '.join(names)}")


def is_number(value: Any) -> bool:
    """Whether ``value`` is a finite number of a TOML table (not a boolean)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def check_keys(table: dict, valid: tuple[str, ...], where: str) -> None:
    """Raise ``UsageError`` naming the first key of ``table`` not in ``valid`` (``where.key``)."""
    unknown = sorted(set(table) - set(valid))
    if unknown:
        raise UsageError(f"{where}.{unknown[0]}: unknown key; valid keys: {', '.join(valid)}")


def _as_list(value: Any) -> list:
    return value if isinstance(value, list) else [value]


def parse_objective(table: dict, where: str) -> Objective:
    """The objective of a spec's (or a results line's) ``objective`` table: ``metric``,
    ``penalty`` and ``constraint`` (each a table or a list of tables); one line naming the key
    on anything else."""
    check_keys(table, ("metric", "penalty", "constraint"), f"{where}: objective")
    metric = table.get("metric", "rms_error_mm")
    if not isinstance(metric, str) or not metric:
        raise UsageError(f"{where}: objective.metric must be a metric name such as "
                         "'rms_error_mm'")
    penalties = []
    for item in _as_list(table.get("penalty", [])):
        here = f"{where}: objective.penalty"
        if not isinstance(item, dict):
            raise UsageError(f"{here} must be a table {{metric, weight, limit}}")
        check_keys(item, ("metric", "weight", "limit"), here)
        if not isinstance(item.get("metric"), str):
            raise UsageError(f"{here}.metric: missing or not a string")
        weight, limit = item.get("weight"), item.get("limit", 0.0)
        if not is_number(weight) or weight < 0:
            raise UsageError(f"{here}.weight must be a number >= 0, got {weight!r}")
        if not is_number(limit):
            raise UsageError(f"{here}.limit must be a number, got {limit!r}")
        penalties.append(Penalty(item["metric"], float(weight), float(limit)))
    constraints = []
    for item in _as_list(table.get("constraint", [])):
        here = f"{where}: objective.constraint"
        if not isinstance(item, dict):
            raise UsageError(f"{here} must be a table {{metric, max, min}}")
        check_keys(item, ("metric", "max", "min"), here)
        if not isinstance(item.get("metric"), str):
            raise UsageError(f"{here}.metric: missing or not a string")
        bounds = {k: item.get(k) for k in ("max", "min")}
        if all(v is None for v in bounds.values()):
            raise UsageError(f"{here}: give max and/or min")
        for k, v in bounds.items():
            if v is not None and not is_number(v):
                raise UsageError(f"{here}.{k} must be a number, got {v!r}")
        constraints.append(Constraint(item["metric"], _opt_float(bounds["max"]),
                                      _opt_float(bounds["min"])))
    return Objective(metric, tuple(penalties), tuple(constraints))


def _opt_float(value: Any) -> float | None:
    return None if value is None else float(value)
