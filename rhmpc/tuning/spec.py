"""Parameter sweeps over run settings: the ``rhmpc tune`` specification and its evaluations.

A sweep specification (TOML) names

- ``base`` — the run settings every evaluation starts from: an inline table laid out like a
  ``simulate --config`` file, or the path of such a file (relative to the spec);
- ``parameters`` — the settings to vary, as dotted keys (``"mpc.effort_weight"``) or nested
  tables (``[parameters.mpc]``). A list is a set of values (a grid axis, or the choices of a
  sampler); a table ``{low, high, scale = "linear"|"log", integer = false, num = N}`` is a
  range: sampled by ``random``/``lhs``, or ``num`` evenly spaced values on a grid;
- ``sampler`` — ``method`` (``"grid"`` default, ``"random"``, ``"lhs"`` Latin hypercube),
  ``budget`` (points drawn by random/lhs), ``seed`` (of the sampler's
  ``numpy.random.Generator``), ``include_base`` (also evaluate the base settings);
- ``evaluate`` — ``scenarios`` (names; default the base's scenario) and ``seeds`` (a list, or a
  count ``S`` for seeds 0…S−1; default the base's seed): every point runs on each;
- ``objective`` — ``metric`` to minimise (a key of the run document, dotted for nested ones such
  as ``"tick_us.p99"``), optional ``penalty`` (``{metric, weight, limit}``: adds
  ``weight · max(0, value − limit)`` per evaluation) and ``constraint`` (``{metric, max}`` and/or
  ``min``, on the mean over a point's evaluations; violators rank after all feasible points).
  Either may be a list of such tables.

The objective lives in :mod:`rhmpc.tuning.objective`, one evaluation (task, key, results line)
in :mod:`rhmpc.tuning.evaluate`.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rhmpc.errors import UsageError
from rhmpc.experiment import SECTIONS, RunConfig, load_config, read_toml
from rhmpc.experiment.run import jsonable
from rhmpc.tuning.evaluate import Task, apply_point, current_value, evaluation_key
from rhmpc.tuning.objective import Objective, check_keys, is_number, parse_objective

__all__ = [
    "Parameter",
    "TuneSpec",
    "load_spec",
    "parse_spec",
    "with_sampler_seed",
]

#: Most evaluations (points × scenarios × seeds) one sweep may hold; split a larger sweep.
MAX_EVALUATIONS = 20_000

SPEC_KEYS = ("name", "base", "parameters", "sampler", "evaluate", "objective")
SAMPLERS = ("grid", "random", "lhs")
_DICT_SECTIONS = ("sensor_settings", "predictor_settings")


# --------------------------------------------------------------------------- spec objects


@dataclass(frozen=True)
class Parameter:
    """One setting to vary.

    Attributes
    ----------
    key : str
        Dotted setting name as accepted by :meth:`RunConfig.replace` (``"mpc.effort_weight"``).
    values : tuple | None
        The explicit values (a grid axis / the choices of a sampler), or ``None`` for a range.
    low, high : float | None
        Range bounds, in the setting's own unit (SI).
    scale : str
        ``"linear"`` or ``"log"`` spacing/sampling of a range.
    integer : bool
        Round range values to integers.
    num : int | None
        Number of grid values of a range (``None``: the range is only for random/lhs).
    """

    key: str
    values: tuple | None = None
    low: float | None = None
    high: float | None = None
    scale: str = "linear"
    integer: bool = False
    num: int | None = None

    @property
    def is_range(self) -> bool:
        return self.values is None

    def axis_length(self) -> int:
        """How many values this parameter takes on a grid (at most), without listing them."""
        if self.values is not None:
            return len(self.values)
        assert self.num is not None
        if self.integer:
            return min(self.num, math.floor(self.high) - math.ceil(self.low) + 1)
        return self.num

    def grid(self) -> tuple:
        """The values this parameter takes on a grid."""
        if self.values is not None:
            return self.values
        assert self.num is not None
        u = np.linspace(0.0, 1.0, self.num) if self.num > 1 else np.array([0.5])
        return tuple(dict.fromkeys(self.from_unit(x) for x in u))

    def from_unit(self, u: float) -> Any:
        """Map ``u`` in [0, 1] onto the range (or onto the list's index)."""
        if self.values is not None:
            return self.values[min(int(u * len(self.values)), len(self.values) - 1)]
        lo, hi = float(self.low), float(self.high)
        if self.scale == "log":
            x = math.exp(math.log(lo) + u * (math.log(hi) - math.log(lo)))
        else:
            x = lo + u * (hi - lo)
        if self.integer:
            return int(min(max(round(x), math.ceil(lo)), math.floor(hi)))
        return float(min(max(x, lo), hi))


@dataclass(frozen=True)
class TuneSpec:
    """A parsed sweep specification (see the module docstring for the TOML layout).

    Attributes
    ----------
    name : str
        Label of the sweep (default: the spec file's stem).
    base : RunConfig
        Settings every point starts from.
    parameters : tuple[Parameter, ...]
        Settings to vary.
    sampler : str
        ``"grid"``, ``"random"`` or ``"lhs"``.
    budget : int | None
        Points drawn by random/lhs.
    sampler_seed : int
        Seed of the sampler's generator.
    include_base : bool
        Also evaluate the base settings as a point.
    scenarios : tuple[str, ...]
        Scenarios each point is evaluated on (empty: the base's own scenario or recording).
    seeds : tuple[int, ...]
        Run seeds each point is evaluated with.
    objective : Objective
        What is minimised.
    """

    name: str
    base: RunConfig
    parameters: tuple[Parameter, ...]
    sampler: str = "grid"
    budget: int | None = None
    sampler_seed: int = 0
    include_base: bool = False
    scenarios: tuple[str, ...] = ()
    seeds: tuple[int, ...] = (0,)
    objective: Objective = field(default_factory=Objective)

    def points(self) -> list[dict[str, Any]]:
        """The parameter assignments to evaluate, deterministic for a given spec."""
        params = self.parameters
        if self.sampler == "grid":
            axes = [p.grid() for p in params]
            out = [dict(zip((p.key for p in params), combo, strict=True))
                   for combo in itertools.product(*axes)]
        else:
            rng = np.random.default_rng(self.sampler_seed)
            n = int(self.budget or 0)
            if self.sampler == "random":
                u = rng.random((n, len(params)))
            else:  # Latin hypercube: one sample per stratum and parameter
                u = np.empty((n, len(params)))
                for j in range(len(params)):
                    u[:, j] = (rng.permutation(n) + rng.random(n)) / n
            out = [{p.key: p.from_unit(float(u[i, j])) for j, p in enumerate(params)}
                   for i in range(n)]
        return out

    def base_values(self) -> dict[str, Any]:
        """The base settings' value of every parameter."""
        return {p.key: current_value(self.base, p.key) for p in self.parameters}

    def evaluations(self) -> list[tuple[str, int]]:
        """(scenario, seed) pairs each point runs on."""
        scenarios = self.scenarios or (self.base.scenario,)
        return [(s, seed) for s in scenarios for seed in self.seeds]

    def tasks(self) -> list[Task]:
        """Every evaluation of the sweep, points in order, duplicates removed."""
        points = [(p, False) for p in self.points()]
        if self.include_base:
            points.insert(0, (self.base_values(), True))
        tasks: list[Task] = []
        seen: dict[str, int] = {}
        for assignment, is_base in points:
            config = apply_point(self.base, assignment)
            point_key = evaluation_key(config, point=True)
            if point_key in seen:
                if is_base:  # the grid already holds the base point: flag it
                    tasks = [dataclasses.replace(t, base=True) if t.point == point_key else t
                             for t in tasks]
                continue
            seen[point_key] = len(tasks)
            for index, (scenario, seed) in enumerate(self.evaluations()):
                run = config.replace(scenario=scenario, seed=seed)
                tasks.append(Task(evaluation_key(run), point_key, index, jsonable(assignment),
                                  run.to_dict(), is_base))
        return tasks


# --------------------------------------------------------------------------- parsing


def load_spec(path: str | Path) -> TuneSpec:
    """Read and validate a sweep specification; errors name the file and the key."""
    path = Path(path)
    return parse_spec(read_toml(path, "tune spec"), where=str(path), root=path.parent,
                      default_name=path.stem)


def parse_spec(data: dict, where: str = "spec", root: Path | None = None,
               default_name: str = "tune") -> TuneSpec:
    """Build a :class:`TuneSpec` from a parsed TOML document.

    Raises
    ------
    UsageError
        Naming ``where`` and the offending key.
    """
    unknown = sorted(set(data) - set(SPEC_KEYS))
    if unknown:
        raise UsageError(f"{where}: unknown key {unknown[0]!r}; valid keys: {', '.join(SPEC_KEYS)}")
    name = data.get("name", default_name)
    if not isinstance(name, str) or not name:
        raise UsageError(f"{where}: name must be a non-empty string")
    base = _parse_base(data.get("base", {}), where, root or Path("."))
    parameters = _parse_parameters(data.get("parameters", {}), where)
    sampler = _table(data, "sampler", where)
    check_keys(sampler, ("method", "budget", "seed", "include_base"), f"{where}: sampler")
    method = sampler.get("method", "grid")
    if method not in SAMPLERS:
        raise UsageError(f"{where}: sampler.method must be one of {', '.join(SAMPLERS)}, "
                         f"got {method!r}")
    budget = sampler.get("budget")
    seed = sampler.get("seed", 0)
    include_base = sampler.get("include_base", False)
    if not isinstance(include_base, bool):
        raise UsageError(f"{where}: sampler.include_base must be true or false")
    if not _is_int(seed):
        raise UsageError(f"{where}: sampler.seed must be an integer, got {seed!r}")
    if method == "grid":
        if budget is not None:
            raise UsageError(f"{where}: sampler.budget applies to method 'random' or 'lhs', "
                             "not to a grid")
        for p in parameters:
            if p.is_range and p.num is None:
                raise UsageError(f"{where}: parameters.{p.key}: a range on a grid needs num "
                                 "(or use sampler.method = 'random' or 'lhs' with a budget)")
    elif not _is_int(budget) or budget < 1:
        raise UsageError(f"{where}: sampler.budget must be an integer >= 1 for method "
                         f"{method!r}, got {budget!r}")
    if not parameters and not include_base:
        raise UsageError(f"{where}: parameters: nothing to vary (add parameters, or set "
                         "sampler.include_base = true)")
    scenarios, seeds = _parse_evaluate(_table(data, "evaluate", where), base, where)
    objective = parse_objective(_table(data, "objective", where), where)
    spec = TuneSpec(name, base, parameters, method, budget, int(seed), include_base,
                    scenarios, seeds, objective)
    _check_size(spec, where)
    _validate_points(spec, where)
    return spec


def with_sampler_seed(spec: TuneSpec, seed: int, where: str = "spec") -> TuneSpec:
    """``spec`` with another sampler seed (``rhmpc tune --seed``), its points validated."""
    out = dataclasses.replace(spec, sampler_seed=int(seed))
    _validate_points(out, where)
    return out


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _table(data: dict, key: str, where: str) -> dict:
    value = data.get(key, {})
    if not isinstance(value, dict):
        raise UsageError(f"{where}: {key} must be a table")
    return value


def _parse_base(value: Any, where: str, root: Path) -> RunConfig:
    if isinstance(value, str):
        path = Path(value)
        if not path.is_absolute():
            path = root / path
        if not path.is_file():
            raise UsageError(f"{where}: base: no such file {str(path)!r}")
        return load_config(path)
    if isinstance(value, dict):
        return RunConfig.from_dict(value, where=f"{where}: base")
    raise UsageError(f"{where}: base must be a table of run settings or the path of a "
                     "simulate --config file")


def _flatten_parameters(table: dict, prefix: str = "") -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    for key, value in table.items():
        dotted = f"{prefix}{key}"
        if (not prefix and key in (*SECTIONS, *_DICT_SECTIONS) and isinstance(value, dict)
                and not ({"low", "high"} & set(value))):
            out.extend(_flatten_parameters(value, prefix=f"{dotted}."))
        else:
            out.append((dotted, value))
    return out


_RANGE_KEYS = ("low", "high", "scale", "integer", "num")


def _parse_parameters(table: Any, where: str) -> tuple[Parameter, ...]:
    if not isinstance(table, dict):
        raise UsageError(f"{where}: parameters must be a table")
    out = []
    for key, value in _flatten_parameters(table):
        here = f"{where}: parameters.{key}"
        if key in ("scenario", "seed"):
            raise UsageError(f"{here}: set the {key}s to evaluate on in "
                             f"evaluate.{key}s, not as a parameter")
        if isinstance(value, list):
            if not value:
                raise UsageError(f"{here}: the list of values is empty")
            out.append(Parameter(key, values=tuple(jsonable(v) for v in value)))
        elif isinstance(value, dict):
            check_keys(value, _RANGE_KEYS, here)
            lo, hi = value.get("low"), value.get("high")
            if not (is_number(lo) and is_number(hi)):
                raise UsageError(f"{here}: a range needs numbers low and high")
            if not lo < hi:
                raise UsageError(f"{here}: low must be < high, got {lo} >= {hi}")
            scale = value.get("scale", "linear")
            if scale not in ("linear", "log"):
                raise UsageError(f"{here}: scale must be 'linear' or 'log', got {scale!r}")
            if scale == "log" and lo <= 0:
                raise UsageError(f"{here}: a log range needs low > 0")
            integer = value.get("integer", _is_int(lo) and _is_int(hi))
            if not isinstance(integer, bool):
                raise UsageError(f"{here}: integer must be true or false")
            if integer and math.floor(hi) < math.ceil(lo):
                raise UsageError(f"{here}: no integer in [{lo}, {hi}]")
            num = value.get("num")
            if num is not None and (not _is_int(num) or num < 1):
                raise UsageError(f"{here}: num must be an integer >= 1, got {num!r}")
            out.append(Parameter(key, None, float(lo), float(hi), scale, integer, num))
        else:
            raise UsageError(f"{here}: expected a list of values or a range table "
                             "{low, high, ...}, got " + repr(value))
    return tuple(out)


def _parse_evaluate(table: dict, base: RunConfig, where: str) -> tuple[tuple[str, ...],
                                                                       tuple[int, ...]]:
    from rhmpc.sim.heart import SCENARIOS

    check_keys(table, ("scenarios", "seeds"), f"{where}: evaluate")
    scenarios = table.get("scenarios", [])
    if isinstance(scenarios, str):
        scenarios = [scenarios]
    if not isinstance(scenarios, list) or not all(isinstance(s, str) for s in scenarios):
        raise UsageError(f"{where}: evaluate.scenarios must be a list of scenario names")
    unknown = [s for s in scenarios if s not in SCENARIOS]
    if unknown:
        raise UsageError(f"{where}: evaluate.scenarios: unknown scenario {unknown[0]!r}; valid: "
                         f"{', '.join(SCENARIOS)}")
    if scenarios and base.data is not None:
        raise UsageError(f"{where}: evaluate.scenarios: the base tracks a recording "
                         f"({base.data}); scenarios would be ignored")
    seeds = table.get("seeds", [base.seed])
    if _is_int(seeds):
        if seeds < 1:
            raise UsageError(f"{where}: evaluate.seeds: a count must be >= 1, got {seeds}")
        seeds = list(range(seeds))
    if not isinstance(seeds, list) or not seeds or not all(_is_int(s) for s in seeds):
        raise UsageError(f"{where}: evaluate.seeds must be a count or a list of integers")
    return tuple(dict.fromkeys(scenarios)), tuple(dict.fromkeys(seeds))


def _check_size(spec: TuneSpec, where: str) -> None:
    """Refuse a sweep of more than :data:`MAX_EVALUATIONS` evaluations before drawing a point,
    saying how long it would take."""
    from rhmpc.tuning.progress import format_duration

    if spec.sampler == "grid":
        axes = [p.axis_length() for p in spec.parameters]
        points = math.prod(axes)
        what = f"parameters: a grid of {' × '.join(map(str, axes)) or '1'} points"
    else:
        points = int(spec.budget or 0)
        what = f"sampler.budget = {points:,} points"
    points += spec.include_base
    per_point = len(spec.evaluations())
    total = points * per_point
    if total <= MAX_EVALUATIONS:
        return
    cores = os.cpu_count() or 1
    wall = total * spec.base.loop.duration / cores
    raise UsageError(f"{where}: {what} × {per_point} evaluation(s) each = {total:,} "
                     f"evaluations, above the limit of {MAX_EVALUATIONS:,} per sweep (at real-time "
                     f"speed on {cores} core(s) they would take {format_duration(wall)}); lower "
                     "it, or split the sweep")


def _validate_points(spec: TuneSpec, where: str) -> None:
    """Every parameter and every point must build a valid run configuration."""
    from rhmpc.predictors.registry import settings_for

    for p in spec.parameters:
        values = p.grid() if (p.values is not None or p.num) else (p.from_unit(0.0),
                                                                    p.from_unit(1.0))
        for value in values:
            try:
                apply_point(spec.base, {p.key: value})
            except UsageError as exc:
                raise UsageError(f"{where}: parameters.{p.key} = {value!r}: {exc}") from None
    for assignment in spec.points():
        try:
            config = apply_point(spec.base, assignment)
            if config.predictor != "exact":
                settings_for(config.predictor, **dict(config.predictor_settings))
        except (UsageError, TypeError, ValueError) as exc:
            text = ", ".join(f"{k} = {v!r}" for k, v in assignment.items())
            raise UsageError(f"{where}: parameters ({text}): {exc}") from None
