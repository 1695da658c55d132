"""One evaluation of a sweep: its task, its settings key, and the results line it writes.

An *evaluation* is one point on one scenario with one seed: a complete :class:`RunConfig`. Its key
is a hash of all its settings (predictor settings resolved to their full dataclass, so that a
default written out and a default left implicit are the same evaluation); the *point* key hashes
the same settings without scenario and seed.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import threading
import time
import traceback
from dataclasses import dataclass
from typing import Any

from rhmpc.experiment import SECTIONS, RunConfig
from rhmpc.experiment.run import jsonable
from rhmpc.experiment.tables import to_dict as settings_to_dict

__all__ = ["RUN_LOCK", "Task", "apply_point", "current_value", "evaluate_task",
           "evaluation_key", "record_for"]

#: Record format version written into every results line.
RECORD_FORMAT = 1

#: Document entries that are not metrics (kept elsewhere in a record, or too bulky).
_NOT_METRICS = ("settings", "versions", "predictor", "scenario", "robot", "seed", "sensor",
                "ground_truth", "controller", "predictor_counts", "wall_s")


@dataclass(frozen=True)
class Task:
    """One evaluation: a point's settings on one scenario with one seed.

    Attributes
    ----------
    key : str
        Hash of the evaluation's full settings.
    point : str
        Hash of the point's settings (without scenario and seed).
    index : int
        Position of (scenario, seed) among the point's evaluations.
    parameters : dict
        The varied settings of the point (dotted keys).
    settings : dict
        The complete :meth:`RunConfig.to_dict`.
    base : bool
        True for the spec's base settings (``sampler.include_base``).
    """

    key: str
    point: str
    index: int
    parameters: dict
    settings: dict
    base: bool = False

    @property
    def config(self) -> RunConfig:
        return RunConfig.from_dict(self.settings, where=f"evaluation {self.key}")


# --------------------------------------------------------------------------- settings helpers


def current_value(config: RunConfig, key: str) -> Any:
    """The value of dotted setting ``key`` in ``config`` (predictor settings resolved)."""
    section, _, name = key.partition(".")
    if not name:
        return jsonable(getattr(config, section))
    if section in SECTIONS:
        return jsonable(getattr(getattr(config, section), name))
    if section == "predictor_settings":
        if name in config.predictor_settings:
            return jsonable(config.predictor_settings[name])
        resolved = resolved_predictor_settings(config)
        return jsonable(resolved.get(name)) if resolved is not None else None
    return jsonable(config.sensor_settings.get(name))


def resolved_predictor_settings(config: RunConfig) -> dict | None:
    """The predictor's complete settings as a dict, or ``None`` if they cannot be resolved."""
    from rhmpc.predictors.registry import settings_for

    try:
        return settings_to_dict(settings_for(config.predictor, **dict(config.predictor_settings)))
    except (TypeError, ValueError):
        return None


def apply_point(base: RunConfig, assignment: dict[str, Any]) -> RunConfig:
    """``base`` with the parameter values of ``assignment``."""
    return base.replace(**assignment) if assignment else base


def evaluation_key(config: RunConfig, point: bool = False) -> str:
    """Stable hash of every setting of ``config`` (without scenario and seed if ``point``)."""
    data = config.to_dict()
    resolved = resolved_predictor_settings(config)
    if resolved is not None:
        data["predictor_settings"] = resolved
    if point:
        data.pop("scenario", None)
        data.pop("seed", None)
    text = json.dumps(jsonable(data), sort_keys=True, separators=(",", ":"), allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()[:20]


# --------------------------------------------------------------------------- evaluation


def _metrics(document: dict) -> dict:
    return {k: v for k, v in document.items() if k not in _NOT_METRICS}


_VERSIONS: dict[str, str] | None = None


def _versions() -> dict[str, str]:
    """:func:`rhmpc.experiment.versions`, looked up once per process."""
    global _VERSIONS
    if _VERSIONS is None:
        from rhmpc.experiment import versions

        _VERSIONS = versions()
    return dict(_VERSIONS)


def record_for(task: Task, status: str, **fields: Any) -> dict:
    """A results line for ``task`` (``status`` ``"ok"`` or ``"failed"``)."""
    return {
        "format": RECORD_FORMAT,
        "key": task.key,
        "point": task.point,
        "index": task.index,
        "status": status,
        "base": task.base,
        "parameters": task.parameters,
        "scenario": task.settings.get("scenario"),
        "data": task.settings.get("data"),
        "seed": task.settings.get("seed"),
        **fields,
        "settings": task.settings,
        "versions": _versions(),
    }


#: One closed-loop run at a time per process: the run stack is not thread-safe (two runs in
#: threads of one process corrupt the heap), and a Dask worker may have several threads.
RUN_LOCK = threading.Lock()


def evaluate_task(task: Task, extra: dict | None = None) -> dict:
    """Run one evaluation (in a worker) and return its results line.

    Exceptions of the run are caught and recorded (status ``"failed"`` with the error and the
    traceback's last lines); ``KeyboardInterrupt`` and other non-``Exception`` errors propagate.
    ``extra`` entries (e.g. the sweep's name and objective) are added to the record. Runs in
    one process are serialised (:data:`RUN_LOCK`); give Dask workers one thread each
    (``dask worker --nthreads 1 --nworkers N``) to use N cores.
    """
    from rhmpc.experiment import run_experiment

    with RUN_LOCK:
        started = time.time()
        wall = time.perf_counter()
        timing = {"started": started, "host": platform.node(), "pid": os.getpid()}
        try:
            _, document = run_experiment(task.config)
        except Exception as exc:
            tb = traceback.format_exc().strip().splitlines()
            return record_for(task, "failed", **(extra or {}),
                              error=f"{type(exc).__name__}: {exc}", traceback=tb[-6:],
                              timing={**timing, "wall_s": time.perf_counter() - wall})
        return record_for(task, "ok", **(extra or {}), metrics=jsonable(_metrics(document)),
                          scenario_label=document.get("scenario"),
                          timing={**timing, "wall_s": time.perf_counter() - wall,
                                  "run_wall_s": document.get("wall_s")})
