"""rhmpc: receding-horizon MPC for robot-assisted beating-heart surgery.

The package's parts (``docs/design/index.md`` maps what each may import):

- :mod:`rhmpc.control` — the controller: QP, per-tick MPC, reference builder, settings;
- :mod:`rhmpc.experiment` — one run's configuration (TOML) and its assembly;
- :mod:`rhmpc.studies` — bench, prediction studies, the Tables I–III comparison;
- :mod:`rhmpc.tuning` — resumable parameter sweeps;
- :mod:`rhmpc.cli` — the ``rhmpc`` console script.

The most used names are importable from here (``from rhmpc import RecedingHorizonMPC``); they
load on first use.
"""

from __future__ import annotations

import importlib
from importlib.metadata import PackageNotFoundError, version
from typing import Any

try:
    __version__ = version("rhmpc")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

_EXPORTS = {
    "MPCSettings": "rhmpc.control.settings",
    "RecedingHorizonMPC": "rhmpc.control.mpc",
    "ExactReference": "rhmpc.control.reference",
    "PredictedReference": "rhmpc.control.reference",
    "RunConfig": "rhmpc.experiment",
    "load_config": "rhmpc.experiment",
    "run_experiment": "rhmpc.experiment",
}

__all__ = ["__version__", *sorted(_EXPORTS)]


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
