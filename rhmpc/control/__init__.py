"""The controller: its description in Python, its tick in the C library generated from it.

- :mod:`~rhmpc.control.settings` — :class:`MPCSettings` and the dataclass ↔ dict helpers;
- :mod:`~rhmpc.control.qp` — the condensed QP, built once (CasADi);
- :mod:`~rhmpc.control.envelope` — joint position/velocity and Cartesian limits as soft rows;
- :mod:`~rhmpc.control.mpc` — :class:`RecedingHorizonMPC`, the QP and the screening cascade's data;
- :mod:`~rhmpc.control.observer` — the observer's gains and innovation gate;
- :mod:`~rhmpc.control.cancellation` — the controller's model of the arm's nonlinearities;
- :mod:`~rhmpc.control.reference` — the reference's settings and a predictor driving it;
- :mod:`~rhmpc.control.controller` — :class:`Controller`, the binding to the library;
- :mod:`~rhmpc.control.export` — the generator of that library (``rhmpc export``).

Imports only :mod:`rhmpc.robots`, :mod:`rhmpc.predictors` and :mod:`rhmpc.compiled` (the library's
build). The names below load on first use, so that ``rhmpc.control.settings`` stays cheap to import.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "MPCSettings": "rhmpc.control.settings",
    "CondensedQP": "rhmpc.control.qp",
    "build_condensed_qp": "rhmpc.control.qp",
    "Controller": "rhmpc.control.controller",
    "RecedingHorizonMPC": "rhmpc.control.mpc",
    "PredictedReference": "rhmpc.control.reference",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
