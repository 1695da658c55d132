"""The controller: the MPC's QP (formulated once with CasADi), the per-tick controller (the
exact screening cascade, OSQP, fallbacks), the reference builder, and their settings.

- :mod:`~rhmpc.control.settings` — :class:`MPCSettings` and the dataclass ↔ dict helpers;
- :mod:`~rhmpc.control.qp` — the condensed QP, built once (CasADi);
- :mod:`~rhmpc.control.envelope` — joint position/velocity and Cartesian limits as soft rows;
- :mod:`~rhmpc.control.offset` — the output offset from forward kinematics (offset-free MPC);
- :mod:`~rhmpc.control.box_qp` — level 2 of the cascade, the torque-box QP by active set;
- :mod:`~rhmpc.control.osqp_solver` — level 3, OSQP set up once;
- :mod:`~rhmpc.control.fallback` — :class:`MPCStats`, the fallback torques;
- :mod:`~rhmpc.control.mpc` — :class:`RecedingHorizonMPC`, the per-tick controller;
- :mod:`~rhmpc.control.reference` — the N-point reference from a predictor or the true future.

Imports only :mod:`rhmpc.robots`, :mod:`rhmpc.predictors` and :mod:`rhmpc.compiled` (the export's
build). The names below load on first use, so that ``rhmpc.control.settings`` stays cheap to import.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "MPCSettings": "rhmpc.control.settings",
    "CondensedQP": "rhmpc.control.qp",
    "build_condensed_qp": "rhmpc.control.qp",
    "RecedingHorizonMPC": "rhmpc.control.mpc",
    "ExactReference": "rhmpc.control.reference",
    "PredictedReference": "rhmpc.control.reference",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
