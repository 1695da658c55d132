"""Resumable parameter sweeps (``rhmpc tune``).

- :mod:`~rhmpc.tuning.spec` — the sweep specification (TOML) and its points (grid, random, LHS);
- :mod:`~rhmpc.tuning.objective` — what a sweep minimises: metric, penalties, constraints;
- :mod:`~rhmpc.tuning.evaluate` — one evaluation: its task, settings key and results line;
- :mod:`~rhmpc.tuning.store` — the append-only JSON-lines results file;
- :mod:`~rhmpc.tuning.runner` — local processes or a Dask cluster;
- :mod:`~rhmpc.tuning.report` — the ranked table, the best settings, the objective plot.

Imports :mod:`rhmpc.experiment` and the layers below; never :mod:`rhmpc.studies` or
:mod:`rhmpc.cli`.
"""

from rhmpc.tuning.evaluate import Task, evaluate_task, evaluation_key, record_for
from rhmpc.tuning.objective import Constraint, Objective, Penalty, metric_value
from rhmpc.tuning.spec import Parameter, TuneSpec, load_spec, parse_spec, with_sampler_seed

__all__ = [
    "Constraint",
    "Objective",
    "Parameter",
    "Penalty",
    "Task",
    "TuneSpec",
    "evaluate_task",
    "evaluation_key",
    "load_spec",
    "metric_value",
    "parse_spec",
    "record_for",
    "with_sampler_seed",
]
