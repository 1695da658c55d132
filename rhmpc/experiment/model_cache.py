"""Models fitted before the run, kept and found again: the same fit is never run twice.

A fitted predictor's model follows from its kind, its settings (its seed among them, its
``leads`` aside), its sampling period, the series it is fitted on and the code that fits it (the
files of :mod:`rhmpc.predictors.learned` and of its own module); the hash of these names
the model in the cache, ``models/`` of :func:`rhmpc.compiled.cache_dir` (``$RHMPC_CACHE``, by
default ``~/.cache/rhmpc``), one file per fit written in the one model format
(:mod:`rhmpc.predictors.learned.modelfile`) as ``KEY-L<leads>.npz``. So ``rhmpc predict
--data REC --split 600:700`` fits its networks on frames 0–599 once, and ``rhmpc compare
--data REC --split 600:750`` — or ``simulate``, or ``predict`` again — finds them: the same
recording and point, the same frames before TRAIN, the same predictor and seed.

A model fitted for L leads serves any L' ≤ L: each lead's forecast is its own head's (or the
first L' outputs of a joint head), so the one with the fewest leads ≥ L' is taken. A file the
cache cannot read or write is passed over: the model is fitted, as without a cache.
``RHMPC_MODEL_CACHE=off`` turns the cache off.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib
import json
import os
import re
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.compiled import cache_dir

__all__ = ["KEY_VERSION", "fit_or_load", "folder", "lookup", "model_key", "store"]

#: The version of the key's recipe: a change to it (or to how a model is fitted) bumps it.
KEY_VERSION = 1
#: The settings a model does not depend on (the leads are matched separately).
_ASIDE = ("leads", "model", "unit")
_NAME = re.compile(r"^(?P<key>[0-9a-f]{32})-L(?P<leads>[0-9]+)\.npz$")


def folder() -> Path | None:
    """The cache's folder, or None when ``RHMPC_MODEL_CACHE`` is ``off``."""
    if os.environ.get("RHMPC_MODEL_CACHE", "").strip().lower() in ("off", "0", "no"):
        return None
    return cache_dir() / "models"


@functools.cache
def code_hash(module: str) -> str:
    """The hash of the code a fit runs: the fitted predictors' package
    (:mod:`rhmpc.predictors.learned`) and the predictor's own ``module``, file by file."""
    learned = Path(importlib.import_module("rhmpc.predictors.learned").__file__).parent
    files = sorted(learned.glob("*.py"))
    own = Path(importlib.import_module(module).__file__)
    h = hashlib.sha256()
    for path in [*files, *([] if own in files else [own])]:
        h.update(path.name.encode())
        h.update(io.read_bytes(path))
    return h.hexdigest()[:16]


def model_key(predictor, series: Sequence[np.ndarray]) -> str:
    """The hash (32 hex digits) of what ``predictor``'s fit on ``series`` depends on: its kind,
    its settings but ``leads``, ``model`` and ``unit``, its period, every sample, and the code
    that fits it (:func:`code_hash`)."""
    settings = {k: v for k, v in dataclasses.asdict(predictor.settings).items()
                if k not in _ASIDE}
    head = json.dumps({"kind": predictor.KIND, "version": KEY_VERSION, "dt": repr(predictor.dt),
                       "code": code_hash(type(predictor).__module__), "settings": settings},
                      sort_keys=True, default=str)
    h = hashlib.sha256(head.encode())
    for a in series:
        a = np.ascontiguousarray(a, dtype=np.float64)
        h.update(repr(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()[:32]


def lookup(predictor, series: Sequence[np.ndarray]) -> Path | None:
    """The cached model of ``predictor`` fitted on ``series`` with the fewest leads that serve
    its own, or None."""
    where = folder()
    if where is None or not where.is_dir():
        return None
    key, leads = model_key(predictor, series), int(predictor.settings.leads)
    found = []
    for path in where.glob(f"{key}-L*.npz"):
        m = _NAME.match(path.name)
        if m and int(m["leads"]) >= leads:
            found.append((int(m["leads"]), path))
    return min(found)[1] if found else None


def store(predictor, series: Sequence[np.ndarray]) -> Path | None:
    """Keep ``predictor``'s fitted model (fitted on ``series``) in the cache; its path, or None
    when the cache is off or cannot be written (a warning says why)."""
    where = folder()
    if where is None:
        return None
    path = where / f"{model_key(predictor, series)}-L{int(predictor.settings.leads)}.npz"
    try:
        io.make_folder(where, root=where)
        predictor.save(path)
    except (OSError, ValueError) as exc:
        warnings.warn(f"the fitted model is not kept for the next run ({exc})", stacklevel=2)
        return None
    return path


def fit_or_load(predictor, series: Sequence[np.ndarray],
                progress: Callable[[str], None] | None = None) -> Path | None:
    """Load ``predictor``'s model from the cache when it was fitted on ``series`` before (its
    path), else fit it and keep it (None).

    Raises
    ------
    ValueError
        From the fit: too little to fit on.
    """
    path = lookup(predictor, series)
    if path is not None:
        try:
            predictor.load(path)
            return path
        except (OSError, ValueError):  # damaged or from another version: fit it again
            pass
    predictor.fit(series, progress)
    store(predictor, series)
    return None
