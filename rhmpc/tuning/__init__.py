"""Resumable parameter sweeps (``rhmpc tune``).

- :mod:`~rhmpc.tuning.spec` — the sweep specification (TOML) and its points (grid, random, LHS);
- :mod:`~rhmpc.tuning.objective` — what a sweep minimises: metric, penalties, constraints;
- :mod:`~rhmpc.tuning.evaluate` — one evaluation: its task, settings key and results line;
- :mod:`~rhmpc.tuning.store` — the append-only JSON-lines results file;
- :mod:`~rhmpc.tuning.runner` — local processes or a Dask cluster;
- :mod:`~rhmpc.tuning.workers` — local worker processes that die with their parent;
- :mod:`~rhmpc.tuning.progress` — progress bars on stderr, durations and speeds in words;
- :mod:`~rhmpc.tuning.report` — the points' summaries, the ranked table, the best settings;
- :mod:`~rhmpc.tuning.figure` — the objective against the parameters (``--plot``);
- :mod:`~rhmpc.tuning.sweep` — a sweep as ``rhmpc tune`` runs it: its pending evaluations
  with a bar, its points, its speed.

Imports :mod:`rhmpc.experiment` and the layers below; never :mod:`rhmpc.compare` or
:mod:`rhmpc.cli`. The names below load on first use, so that a worker process that needs only
:mod:`~rhmpc.tuning.workers` starts without the run stack.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "Task": "rhmpc.tuning.evaluate",
    "evaluate_task": "rhmpc.tuning.evaluate",
    "evaluation_key": "rhmpc.tuning.evaluate",
    "record_for": "rhmpc.tuning.evaluate",
    "Constraint": "rhmpc.tuning.objective",
    "Objective": "rhmpc.tuning.objective",
    "Penalty": "rhmpc.tuning.objective",
    "metric_value": "rhmpc.tuning.objective",
    "Parameter": "rhmpc.tuning.spec",
    "TuneSpec": "rhmpc.tuning.spec",
    "load_spec": "rhmpc.tuning.spec",
    "parse_spec": "rhmpc.tuning.spec",
    "with_sampler_seed": "rhmpc.tuning.spec",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
