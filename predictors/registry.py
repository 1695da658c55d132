"""Predictors by name: ``make_predictor(name, dt, **settings)``."""

from __future__ import annotations

import dataclasses
from typing import Any

from predictors.ar import AutoregressivePredictor
from predictors.base import Predictor
from predictors.ekf_dual_fourier import DualFourierEKF
from predictors.ekf_fourier import FourierEKF
from predictors.hold import Hold
from predictors.last_cycle import LastCycle
from predictors.oracle import Oracle
from predictors.rls_generalized import GeneralizedRLS
from predictors.rls_one_step import OneStepRLS
from predictors.wflc import WFLC

__all__ = ["PREDICTORS", "make_predictor", "settings_for"]

#: name → (class, default overrides of its settings dataclass)
PREDICTORS: dict[str, tuple[type[Predictor], dict[str, Any]]] = {
    "one-step": (OneStepRLS, {}),
    "generalized": (GeneralizedRLS, {}),
    "ekf": (FourierEKF, {}),
    "dual-ekf": (DualFourierEKF, {}),
    "ar": (AutoregressivePredictor, {}),
    "fading-ar": (AutoregressivePredictor, {"forgetting_factor": 0.985}),
    "last-cycle": (LastCycle, {}),
    "wflc": (WFLC, {}),
    "hold": (Hold, {}),
    "exact": (Oracle, {}),
}

#: the parameter set used when ``params`` is not given
DEFAULT_PARAMS = {"ekf": "adaptive", "dual-ekf": "adaptive", "wflc": "adaptive",
                  "last-cycle": "anchored"}


def settings_for(name: str, **settings: Any):
    """The frozen settings dataclass ``make_predictor(name, …)`` would use."""
    if name not in PREDICTORS:
        raise ValueError(f"unknown predictor {name!r}; valid: {', '.join(PREDICTORS)}")
    cls, overrides = PREDICTORS[name]
    presets = getattr(cls, "PRESETS", None)
    params = settings.pop("params", DEFAULT_PARAMS.get(name))
    if params is not None:
        if not presets:
            raise ValueError(f"{name!r} takes no parameter set (`params`)")
        if params not in presets:
            raise ValueError(f"unknown {name} params {params!r}; valid: {', '.join(presets)}")
        base = presets[params]
    else:
        base = None
    valid = [f.name for f in dataclasses.fields(cls.Settings)]
    unknown = sorted(set(settings) - set(valid))
    if unknown:
        valid += ["params"] if presets else []
        raise ValueError(
            f"unknown setting(s) {', '.join(unknown)} for {name!r}; valid: {', '.join(valid)}"
        )
    merged = {**overrides, **settings}
    return cls.Settings(**merged) if base is None else dataclasses.replace(base, **merged)


def make_predictor(name: str, dt: float, **settings: Any) -> Predictor:
    """Build the predictor ``name`` running at period ``dt`` [s] with ``settings``.

    Unknown names and settings raise ``ValueError`` listing the valid ones.  A predictor with
    parameter sets takes ``params=`` one of its class's ``PRESETS`` (``ekf``: ``"adaptive"``,
    the default, ``"tuna2013-hrv"``, ``"tuna2013"``, ``"yuen2008"``; ``dual-ekf``: ``"adaptive"``,
    ``"fitted"``, ``"richa2010"``; ``wflc``: ``"adaptive"``, ``"pll"``, ``"yuen2009"``;
    ``last-cycle``: ``"anchored"``, ``"yuen2008"``); other settings override it.
    """
    cls = PREDICTORS[name][0] if name in PREDICTORS else None
    s = settings_for(name, **settings)
    return cls(dt, s)
