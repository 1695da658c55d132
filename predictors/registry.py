"""Predictors by name: ``make_predictor(name, dt, **settings)``.

A name is resolved in one place, :func:`resolve`: into the predictor's class and its frozen
settings (its named parameter set, the registry's overrides, then the caller's settings);
:func:`build` makes the predictor of them, and ``make_predictor`` is the two in one.
``PREDICTORS`` holds the online predictors (ready to run once built), ``LEARNED`` the ones
fitted before the run (``fit`` or a ``model`` file, :mod:`rhmpc.predictors.learned`); the neural
ones are imported only when one is built, and need PyTorch (``pip install "rhmpc[learned]"``).
``family(name)`` tells the kind of each: ``baseline``, ``adaptive``, ``multi-point``,
``learned`` or ``combination``. ``load_model(path)`` builds the fitted predictor a file saved
(:mod:`rhmpc.predictors.learned.modelfile`: the one loader, which checks a file before it reads it).
"""

from __future__ import annotations

import dataclasses
import importlib
import importlib.util
from typing import Any, NamedTuple

from rhmpc.io import check_kinds
from rhmpc.predictors.ar import AutoregressivePredictor
from rhmpc.predictors.base import Predictor
from rhmpc.predictors.combination import Combination
from rhmpc.predictors.ekf_dual_fourier import DualFourierEKF
from rhmpc.predictors.ekf_fourier import FourierEKF
from rhmpc.predictors.hold import Hold
from rhmpc.predictors.last_cycle import LastCycle
from rhmpc.predictors.learned.ridge import RidgeSettings
from rhmpc.predictors.learned.settings import (
    GRU_PRESETS,
    LSTM_PRESETS,
    TCN_PRESETS,
    NetworkSettings,
)
from rhmpc.predictors.oracle import Oracle
from rhmpc.predictors.rls_generalized import GeneralizedRLS
from rhmpc.predictors.rls_one_step import OneStepRLS
from rhmpc.predictors.rls_spatiotemporal import SpatioTemporalRLS
from rhmpc.predictors.wflc import WFLC

__all__ = ["BASELINES", "FITTED_DEFAULTS", "LEARNED", "PREDICTORS", "build",
           "combination_members", "default_predictors", "family", "load_model", "make_predictor",
           "model_kind", "needs_torch", "predictor_names", "resolve", "settings_for",
           "torch_available"]

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
    "st-rls": (SpatioTemporalRLS, {}),
    "combination": (Combination, {}),
    "hold": (Hold, {}),
    "exact": (Oracle, {}),
}


class Learned(NamedTuple):
    """Where a predictor fitted before the run lives, and its settings (no import needed)."""

    module: str
    cls: str
    settings: type
    presets: dict | None = None


_NEURAL = "rhmpc.predictors.learned.neural"
#: name → the predictors fitted before the run
LEARNED: dict[str, Learned] = {
    "ridge": Learned("rhmpc.predictors.learned.ridge", "Ridge", RidgeSettings),
    "st-ridge": Learned("rhmpc.predictors.learned.ridge", "MultiPointRidge", RidgeSettings),
    "lstm": Learned(_NEURAL, "LSTMPredictor", NetworkSettings, LSTM_PRESETS),
    "st-lstm": Learned(_NEURAL, "MultiPointLSTM", NetworkSettings, LSTM_PRESETS),
    "gru": Learned(_NEURAL, "GRUPredictor", NetworkSettings, GRU_PRESETS),
    "st-gru": Learned(_NEURAL, "MultiPointGRU", NetworkSettings, GRU_PRESETS),
    "tcn": Learned(_NEURAL, "TCNPredictor", NetworkSettings, TCN_PRESETS),
    "st-tcn": Learned(_NEURAL, "MultiPointTCN", NetworkSettings, TCN_PRESETS),
}

#: the parameter set used when ``params`` is not given
DEFAULT_PARAMS = {"ekf": "adaptive", "dual-ekf": "adaptive", "wflc": "adaptive",
                  "last-cycle": "anchored", "lstm": "zhang2022", "st-lstm": "zhang2022",
                  "gru": "li2022", "st-gru": "li2022", "tcn": "xu2026", "st-tcn": "xu2026"}

_FAMILIES = {"hold": "baseline", "last-cycle": "baseline", "exact": "baseline",
             "st-rls": "multi-point", "combination": "combination"}


#: The baselines, first in every table: the newest sample held, and the previous cycle.
BASELINES: tuple[str, ...] = ("hold", "last-cycle")
#: The fitted predictors taken by default when there is something to fit them on: the ridge
#: regressions, and the literature's networks where PyTorch is installed.
FITTED_DEFAULTS: tuple[str, ...] = ("ridge", "st-ridge", "lstm", "st-lstm", "tcn", "st-tcn")
#: The order of the families in the tables.
FAMILIES: tuple[str, ...] = ("baseline", "adaptive", "multi-point", "learned", "combination")


def torch_available() -> bool:
    """Whether PyTorch, the ``learned`` extra of the neural predictors, is installed."""
    return importlib.util.find_spec("torch") is not None


def default_predictors(fitted: bool = False) -> tuple[str, ...]:
    """The baselines, then every other online predictor (the oracle ``exact`` left out), the
    fitted ones of :data:`FITTED_DEFAULTS` if ``fitted`` (the neural ones where PyTorch is
    installed), by family, and the combination last."""
    names = [n for n in PREDICTORS if n != "exact"]
    if fitted:
        names += [n for n in FITTED_DEFAULTS if not needs_torch(n) or torch_available()]
    names = [*BASELINES, *(n for n in names if n not in BASELINES)]
    return tuple(sorted(names, key=lambda n: FAMILIES.index(family(n))))


def combination_members(fitted: bool = True) -> tuple[str, ...]:
    """The combination's default members: the default predictors (:func:`default_predictors`)
    that are neither baselines nor the combination, the open-loop study's and the closed
    loop's alike."""
    return tuple(n for n in default_predictors(fitted)
                 if family(n) not in ("baseline", "combination"))


def predictor_names() -> tuple[str, ...]:
    """Every name ``make_predictor`` knows: the online ones, then those fitted before the run."""
    return (*PREDICTORS, *LEARNED)


def family(name: str) -> str:
    """``baseline``, ``adaptive``, ``multi-point``, ``learned`` or ``combination``."""
    if name not in PREDICTORS and name not in LEARNED:
        raise ValueError(f"unknown predictor {name!r}; valid: {', '.join(predictor_names())}")
    return "learned" if name in LEARNED else _FAMILIES.get(name, "adaptive")


def needs_torch(name: str) -> bool:
    """Whether predictor ``name`` needs PyTorch (the ``learned`` extra)."""
    return name in LEARNED and LEARNED[name].module == _NEURAL


class _Entry(NamedTuple):
    """What a registered name stands for: the name, its settings class, named parameter sets,
    default overrides and default parameter set, and its class (``None``: one of
    :data:`LEARNED`, imported when built)."""

    name: str
    settings: type
    presets: dict | None
    overrides: dict
    params: str | None
    cls: type[Predictor] | None
    learned: Learned | None = None


def _entry(name: str) -> _Entry:
    """The registry's one lookup of a name; an unknown one is a ``ValueError`` listing the
    valid ones."""
    if name in PREDICTORS:
        cls, overrides = PREDICTORS[name]
        return _Entry(name, cls.Settings, getattr(cls, "PRESETS", None), overrides,
                      DEFAULT_PARAMS.get(name), cls)
    if name in LEARNED:
        learned = LEARNED[name]
        return _Entry(name, learned.settings, learned.presets, {}, DEFAULT_PARAMS.get(name),
                      None, learned)
    raise ValueError(f"unknown predictor {name!r}; valid: {', '.join(predictor_names())}")


def _settings(entry: _Entry, settings: dict[str, Any]):
    """The frozen settings of ``entry`` with ``settings``: its parameter set (``params``, or its
    default one), its overrides, then ``settings``."""
    name, settings = entry.name, dict(settings)
    params = settings.pop("params", entry.params)
    base = None
    if params is not None:
        if not entry.presets:
            raise ValueError(f"{name!r} takes no parameter set (`params`)")
        if params not in entry.presets:
            raise ValueError(f"unknown {name} params {params!r}; valid: "
                             f"{', '.join(entry.presets)}")
        base = entry.presets[params]
    valid = [f.name for f in dataclasses.fields(entry.settings)]
    unknown = sorted(set(settings) - set(valid))
    if unknown:
        valid += ["params"] if entry.presets else []
        raise ValueError(
            f"unknown setting(s) {', '.join(unknown)} for {name!r}; valid: {', '.join(valid)}"
        )
    check_kinds(entry.settings, settings)
    merged = {**entry.overrides, **settings}
    return entry.settings(**merged) if base is None else dataclasses.replace(base, **merged)


def settings_for(name: str, **settings: Any):
    """The frozen settings dataclass ``make_predictor(name, …)`` would use."""
    return _settings(_entry(name), settings)


def _learned_class(entry: _Entry) -> type[Predictor]:
    """The class of a predictor fitted before the run, imported now."""
    learned, name = entry.learned, entry.name
    try:
        module = importlib.import_module(learned.module)
    except ModuleNotFoundError as exc:
        if exc.name != "torch" and not str(exc.name).startswith("torch."):
            raise
        raise ImportError(f"predictor {name!r} needs PyTorch: pip install \"rhmpc[learned]\""
                          ) from None
    return getattr(module, learned.cls)


def resolve(name: str, **settings: Any) -> tuple[type[Predictor], Any]:
    """The class of predictor ``name`` and its frozen settings with ``settings`` (see
    :func:`make_predictor`): the one place a name is resolved.

    Raises
    ------
    ValueError
        An unknown name, parameter set or setting (the message lists the valid ones).
    ImportError
        A neural predictor without PyTorch (the message names the extra to install).
    """
    entry = _entry(name)
    made = _settings(entry, settings)  # a bad setting is said before a missing extra
    return entry.cls or _learned_class(entry), made


def build(cls: type[Predictor], settings: Any, dt: float) -> Predictor:
    """A predictor of class ``cls`` running at period ``dt`` [s] with the frozen ``settings``
    of :func:`resolve`; a combination builds its ``members`` by name (by default
    :func:`combination_members`), each given the file of its kind among ``models``."""
    if cls is not Combination:
        return cls(dt, settings)
    if not settings.members:
        settings = dataclasses.replace(settings, members=combination_members())
    files = _models_by_kind(settings.models, settings.members)
    return Combination(dt, settings, [make_predictor(member, dt, **(
        {"model": files[member]} if member in files else {})) for member in settings.members])


def make_predictor(name: str, dt: float, *, data_unit: float | None = None,
                   **settings: Any) -> Predictor:
    """Build the predictor ``name`` running at period ``dt`` [s] with ``settings``.

    ``data_unit``: metres per unit of the samples it will be fed, when the caller knows it (the
    closed loop feeds metres: 1.0); a predictor that would infer its unit from its first
    samples (``unit=None``) takes it instead, unless ``settings`` give one.

    Unknown names and settings raise ``ValueError`` listing the valid ones.  A predictor with
    parameter sets takes ``params=`` one of its class's ``PRESETS`` (``ekf``: ``"adaptive"``,
    the default, ``"tuna2013-hrv"``, ``"tuna2013"``, ``"yuen2008"``; ``dual-ekf``: ``"adaptive"``,
    ``"fitted"``, ``"richa2010"``; ``wflc``: ``"adaptive"``, ``"pll"``, ``"yuen2009"``;
    ``last-cycle``: ``"anchored"``, ``"yuen2008"``; ``lstm``, ``st-lstm``: ``"zhang2022"``, the
    default, ``"xu2026"``; ``gru``, ``st-gru``: ``"li2022"``; ``tcn``, ``st-tcn``:
    ``"xu2026"``); other settings override it.  ``combination`` builds its ``members`` by
    name (by default :func:`combination_members`).  A predictor of ``LEARNED`` must be fitted
    (``fit``) or given a ``model`` file before it runs; a neural one without PyTorch raises
    ``ImportError`` naming the extra to install.
    """
    cls, made = resolve(name, **settings)
    if data_unit is not None and "unit" not in settings and getattr(made, "unit", 1.0) is None:
        made = dataclasses.replace(made, unit=data_unit)
    return build(cls, made, dt)


def model_kind(path) -> str:
    """The predictor name a saved model declares (its file checked, no array read)."""
    from rhmpc.predictors.learned.modelfile import ModelFile

    with ModelFile(path, tuple(LEARNED)) as saved:
        return saved.kind


def _models_by_kind(paths, members) -> dict[str, str]:
    """member name → the file among ``paths`` of its kind; a file of a kind that is no member,
    or two files of one kind, is a ``ValueError`` naming it."""
    out: dict[str, str] = {}
    for path in paths:
        kind = model_kind(path)
        if kind not in members:
            raise ValueError(f"{path}: a {kind} model, and the combination has no {kind} "
                             f"member ({', '.join(members)})")
        if kind in out:
            raise ValueError(f"{path}: a second {kind} model (the first: {out[kind]})")
        out[kind] = str(path)
    return out


def load_model(path, expected_kind: str | tuple[str, ...] | None = None,
               dt: float | None = None) -> Predictor:
    """The fitted predictor saved in ``path`` (``predict --save-models``, ``save``), ready to run.

    Parameters
    ----------
    path : str or Path
        A model file (:mod:`rhmpc.predictors.learned.modelfile`).
    expected_kind : str or tuple of str, optional
        The predictor name(s) of :data:`LEARNED` asked for (``"ridge"``, ``("lstm",
        "st-lstm")``); a file of another kind is refused.
    dt : float, optional
        The period the predictor will run at [s]; a model fitted at another is refused.
        Default: the file's.

    Returns
    -------
    Predictor
        A predictor of :data:`LEARNED` with the file's settings and model (``settings.model``
        names the file); ``reset`` keeps the model.

    Raises
    ------
    ValueError
        (:class:`rhmpc.io.FileError`) In one line naming the file: not a regular file, empty,
        not a model, another kind or period, a damaged or altered file, one larger than the
        bounds (checked before any array is allocated).
    ImportError
        A network's file without PyTorch (``pip install "rhmpc[learned]"``).
    """
    from rhmpc.predictors.learned.modelfile import ModelFile

    with ModelFile(path, expected_kind or tuple(LEARNED)) as saved:
        kind, saved_dt = saved.kind, saved.dt
    return make_predictor(kind, dt=saved_dt if dt is None else dt, model=str(path))
