"""The predictor refresh compiled: the RLS predictors' reference in C, an accelerator.

:class:`~rhmpc.control.reference.PredictedReference` around
:class:`~predictors.rls_generalized.GeneralizedRLS` (Tuna et al. 2013, §VI) or
:class:`~predictors.rls_one_step.OneStepRLS` (§V) is the reference implementation; in the
closed loop each of its slices (update, learning, forecast, interpolation, bookkeeping) is
mostly argument checks and interpreter overhead around a few hundred multiply-adds.
:class:`CompiledReference` runs the same state machine in ``rhmpc/control/refresh.c``, one C call
per slice:

* the outlier gate (:class:`~rhmpc.control.gate.OutlierGate`): a sample whose miss
  ``‖z − ẑ_{n+1|n}‖² > max(floor², 16 e_rms²)`` is treated as missing while the gate is locked,
  the median-rule calibration of the floor, the unlocking after ``max_rejections`` and the
  retraction of z_n when z_{n+1} agrees with ẑ_{n+1|n−1};
* the predictor (:mod:`predictors.base`, :mod:`predictors.delay_line`): the tapped delay line
  with its ramp repair and cubic gap interpolation, the deferred RLS step (Haykin, *Adaptive
  Filter Theory*, Table 10.1, :mod:`predictors.rls`)::

      π = P x,  κ = λ + xᵀπ,  e = y − W x,  W ← W + e πᵀ/κ,  P ← (P − π πᵀ/κ)/λ

  with its ``rls_reset`` and ``rls_bound`` guards, the forecast clipped to the recent range
  (:class:`~predictors.monitor.RangeEnvelope`), the relearning after a non-finite forecast
  and the running RMS miss per lead (:class:`~predictors.monitor.LeadErrorRMS`);
* the reference: ``K = prediction_points + ⌈latency/dt⌉`` forecast points, their
  piecewise-quadratic Lagrange interpolation at ``s = lead + age/dt`` (window
  ``m = clamp(⌊s⌋, 0, nodes − 3)``, ``u = s − m``)::

      r = ½(u−1)(u−2)·z_m − u(u−2)·z_{m+1} + ½u(u−1)·z_{m+2},

  the reference guard and the placement ``r = origin + E r_c``.

Both make the same decisions and numbers up to the summation order of the products (BLAS in
Python, loops in C; near the end of the double range an inf may be a NaN):
``tests/rhmpc/control/test_compiled_reference.py`` compares every refresh on the same streams.
The C file is compiled at first use (:mod:`sim.compiled`) and loaded with :mod:`ctypes`;
without a compiler :func:`compile_reference` returns no twin and says why
(``unavailable_reason``).
"""

from __future__ import annotations

import ctypes
import functools
import math
import sys
import weakref
from collections import Counter
from pathlib import Path

import numpy as np

from predictors.rls_generalized import GeneralizedRLS
from predictors.rls_one_step import OneStepRLS
from rhmpc.control.gate import OutlierGate
from rhmpc.control.reference import PredictedReference, _origin, windows
from sim.compiled import load

__all__ = ["COUNTS", "CompiledReference", "compile_reference", "load_library"]

_SOURCE = Path(__file__).with_name("refresh.c")
#: The names of the C counters, in the order of ``refresh_public_t.counts``.
COUNTS = ("updates", "missing", "outliers_rejected", "gate_unlocked", "retracted",
          "forecast_clamped", "forecast_nonfinite", "rls_reset", "rls_bound", "reference_guard",
          "repaired")
#: Forecast points beyond ``prediction_points`` allocated at creation (a longer forecast, from
#: a longer latency, reallocates the K-sized arrays once).
K_MARGIN = 32
#: The largest sample dimension (the placement embeds d ≤ 3 axes).
MAX_DIM = 3

#: Why the compiled refresh is not available (None while it is, or before the first attempt).
unavailable_reason: str | None = None
_library: ctypes.PyDLL | None = None
_tried = False

_d, _i, _ll, _p = ctypes.c_double, ctypes.c_int, ctypes.c_longlong, ctypes.c_void_p


class _Config(ctypes.Structure):
    """``refresh_config_t`` of rhmpc/control/refresh.c."""

    _fields_ = [
        *((name, _i) for name in ("generalized", "order", "points", "correlated", "hold_init",
                                  "dim", "dcap", "envelope_block")),
        *((name, _d) for name in ("forgetting", "delta", "p_max", "guard_multiple",
                                  "error_memory", "Ts", "dt")),
        *((name, _i) for name in ("horizon", "prediction_points", "span", "kcap")),
        ("guard_speed", _d), ("guard_margin", _d),
        *((name, _i) for name in ("gate", "max_rejections", "relock", "calibration")),
        ("gate_floor", _d), ("min_floor", _d),
    ]


class _Public(ctypes.Structure):
    """``refresh_public_t``: the state read without a call (the head of ``refresh_t``)."""

    _fields_ = [
        ("tick", _ll), ("stamp", _d),  # the arguments of the staged update
        ("counts", _ll * len(COUNTS)), ("first", _ll), ("age_count", _ll), ("age_sum", _d),
        ("floor", _d),
        *((name, _i) for name in ("locked", "ready", "d", "nz", "has_points", "placed",
                                  "failed", "errors_k")),
    ]


def load_library() -> ctypes.PyDLL | None:
    """The compiled refresh, built at the first call (once per source version); None if
    impossible, with the reason in ``unavailable_reason``.

    Loaded as a :class:`ctypes.PyDLL`: the calls keep the GIL (each is about a microsecond,
    and a refresh's state must not be entered by two threads at once).
    """
    global _library, _tried, unavailable_reason
    if _tried:
        return _library
    _tried = True
    library, unavailable_reason = load(_SOURCE, "refresh", ctypes.PyDLL)
    if library is None:
        return None
    signatures = {
        "refresh_create": ([_p], _p), "refresh_free": ([_p], None),
        "refresh_reset": ([_p], None), "refresh_input": ([_p], _p),
        "refresh_update": ([_p, _p, _ll, _d], _i), "refresh_update_input": ([_p], _i),
        "refresh_update_missing": ([_p], _i), "refresh_learn": ([_p], None),
        "refresh_predict": ([_p], None), "refresh_score": ([_p], None),
        "refresh_interpolate": ([_p, _p], _i), "refresh_refresh": ([_p, _p, _ll, _d, _p], _i),
        "refresh_place": ([_p, _p, _p], _i), "refresh_error_rms": ([_p, _p, _i], _i),
        "plan_points": ([_p, _i], _p), "plan_size": ([], ctypes.c_size_t),
    }
    for name, (argtypes, restype) in signatures.items():
        function = getattr(library, name)
        function.argtypes, function.restype = argtypes, restype
    unavailable_reason = None
    _library = library
    return library


def _references(pair: tuple) -> int:
    """References to ``pair[0]`` beyond the pair's own and this call's."""
    return sys.getrefcount(pair[0]) - _FREE


_FREE = 0
_FREE = _references((np.empty(1), 0))  # a buffer referenced by its pair only


class CompiledGate:
    """The outlier gate's state, read-only: ``floor`` [m] (None while calibrating) and
    ``locked`` (:class:`~rhmpc.control.gate.OutlierGate`)."""

    def __init__(self, owner: CompiledReference) -> None:
        self._owner = owner  # keeps the C state alive

    @property
    def floor(self) -> float | None:
        floor = self._owner._public.floor
        return None if math.isnan(floor) else floor

    @property
    def locked(self) -> bool:
        return bool(self._owner._public.locked)


class CompiledPredictor:
    """The compiled predictor, read-only: what the loop and the reports read of a
    :class:`~predictors.base.Predictor` (``counts``, ``forecast_error_rms``, ``ready``, ``d``,
    ``unit``, ``dt``, ``settings``)."""

    def __init__(self, owner: CompiledReference, settings, dt: float, unit: float) -> None:
        self._owner, self.settings, self.dt, self.unit = owner, settings, dt, unit

    @property
    def counts(self) -> Counter:
        """The event counters (only those that occurred, as the Python predictor's Counter)."""
        values = self._owner._public.counts
        return Counter({name: int(v) for name, v in zip(COUNTS, values, strict=True) if v})

    @property
    def ready(self) -> bool:
        return bool(self._owner._public.ready)

    @property
    def d(self) -> int | None:
        return self._owner._public.d or None

    @property
    def forecast_error_rms(self) -> np.ndarray:
        """(K,) running RMS miss per lead after the pending score (NaN where none was scored;
        empty while d is unknown), as :attr:`predictors.base.Predictor.forecast_error_rms`."""
        return self._owner._error_rms()


class CompiledReference:
    """:class:`~rhmpc.control.reference.PredictedReference` of an RLS predictor, in C.

    The Python reference's interface as the closed loop uses it: :meth:`place`, :meth:`reset`,
    :meth:`refresh`, the slices (:meth:`update`, :meth:`learn`, :meth:`predict`,
    :meth:`interpolate`, :meth:`score`), :meth:`horizons`, :attr:`mean_age`, read-only ``gate``
    and ``predictor``, ``monitor`` None; :meth:`slices` for compiled ticks. Build it with
    :func:`compile_reference`.

    Parameters
    ----------
    library : ctypes.PyDLL
        :func:`load_library`.
    reference : PredictedReference
        A fresh Python reference around a GeneralizedRLS or OneStepRLS with a given unit, whose
        settings are copied.
    dim : int, optional
        The samples' dimension when ``settings.dim`` is None (else any d ≤ 3); d is taken from
        the first valid sample, as in Python.

    Notes
    -----
    Points go into one of two arrays in turn; one handed out by :meth:`horizons` (or a view of
    it) is never written while referenced: a fresh array takes its turn. :meth:`update` writes
    its arguments into the C state and makes one call without arguments (cheaper than
    converting them); :meth:`learn`, :meth:`predict` and :meth:`score` are the C functions
    bound to the state, which is freed with the object (``gate`` and ``predictor`` keep it).
    """

    monitor = None

    def __init__(self, library: ctypes.PyDLL, reference: PredictedReference,
                 dim: int | None = None) -> None:
        predictor = reference.predictor
        s = predictor.settings
        self.N, self.Ts, self.dt = reference.N, reference.Ts, reference.dt
        self.refresh_ticks, self.prediction_points = reference.refresh_ticks, \
            reference.prediction_points
        self.guard_speed, self.guard_margin = reference.guard_speed, reference.guard_margin
        self.span = reference._span
        config = _config(reference, dim)
        self._dcap = config.dcap
        address = library.refresh_create(ctypes.byref(config))
        if not address:
            raise MemoryError("refresh_create failed")
        weakref.finalize(self, library.refresh_free, address)
        self._lib, self._ptr = library, ctypes.c_void_p(address)
        self._public = _Public.from_address(address)
        self._z = np.ctypeslib.as_array((_d * config.dcap).from_address(
            library.refresh_input(self._ptr)))
        self._origin_in = np.zeros(3)
        self._shape = (config.dim,) if config.dim else None  # of a sample, once d is known
        self._rms = np.empty(config.kcap)
        self.gate = CompiledGate(self) if config.gate else None
        self.predictor = CompiledPredictor(self, s, predictor.dt, predictor.unit)
        # the slices as C functions bound to this state (no Python frame of their own)
        ptr = self._ptr
        self._update_z = functools.partial(library.refresh_update_input, ptr)
        self._update_none = functools.partial(library.refresh_update_missing, ptr)
        self.learn = functools.partial(library.refresh_learn, ptr)
        self.predict = functools.partial(library.refresh_predict, ptr)
        self.score = functools.partial(library.refresh_score, ptr)
        self._interpolate = functools.partial(library.refresh_interpolate, ptr)
        self._points: np.ndarray | None = None
        self._live = self._spare = (None, 0)
        origin = getattr(reference, "_origin", None)
        if origin is not None:
            self.place(origin)

    # -- the slices ----------------------------------------------------------------------
    def update(self, tick: int, z: np.ndarray | None, stamp: float) -> None:
        """First slice of a refresh: the outlier gate and the predictor's update with the
        sample ``z`` measured at ``stamp`` [s] (None: no new sample)."""
        public = self._public  # the arguments are written into the C state, then one call
        public.tick, public.stamp = tick, stamp
        if z is None:
            code = self._update_none()
        elif z.__class__ is np.ndarray and z.shape == self._shape:
            self._z[:] = z
            code = self._update_z()
        else:
            self._stage(z)
            code = self._update_z()
            if self._shape is None and public.d:
                self._shape = (public.d,)
        if code:
            raise ValueError(self.update_error(code, stamp))

    def _stage(self, z) -> None:
        """Copy a sample of another type or shape into the C state, checking its size."""
        x = np.asarray(z, dtype=float).reshape(-1)
        d = self._public.d
        if d and x.shape[0] != d:
            raise ValueError(f"sample has {x.shape[0]} components, predictor has d={d}")
        if not 1 <= x.shape[0] <= self._dcap:
            raise ValueError(f"sample has {x.shape[0]} components, expected 1 … {self._dcap}")
        self._public.nz = x.shape[0]
        self._z[: x.shape[0]] = x

    def learn(self) -> None:
        """The predictor's deferred RLS step (:meth:`predictors.base.Predictor.learn`)."""

    def predict(self) -> None:
        """The forecast of ``K = prediction_points + ⌈latency/dt⌉`` points of the last update."""

    def score(self) -> None:
        """The forecast-error bookkeeping (:meth:`predictors.base.Predictor.score`)."""

    def interpolate(self) -> None:
        """The points of the last :meth:`predict`: interpolated, guarded, placed."""
        spare = self._spare
        if not spare[1] or _references(spare) > 0:  # new, reshaped, or still referenced
            spare = self._buffer()
        made = self._interpolate(spare[1])
        if made:
            if made < 0:
                raise MemoryError(self.failure)
            self._spare, self._live = self._live, spare
            self._points = spare[0]

    def refresh(self, tick: int, z: np.ndarray | None, stamp: float) -> None:
        """:meth:`update` then :meth:`forecast`."""
        self.update(tick, z, stamp)
        self.predict()
        self.interpolate()

    def forecast(self) -> None:
        """:meth:`predict` then :meth:`interpolate`."""
        self.predict()
        self.interpolate()

    # -- placement and points ------------------------------------------------------------
    def _buffer(self) -> tuple[np.ndarray, int]:
        """A new array for the points, with its address."""
        d = 3 if self._public.placed else self._public.d
        array = np.empty((self.span, d))
        return array, array.ctypes.data

    def place(self, origin) -> None:
        """From now on ``horizon`` returns workspace points origin + E r_c, shape (N, 3) [m]."""
        self._origin_in[:] = _origin(origin)
        self._public.placed = 1
        self._live = self._spare = (None, 0)  # the layout changes: new arrays
        spare = self._buffer()
        if self._lib.refresh_place(self._ptr, self._origin_in.ctypes.data, spare[1]):
            self._live, self._points = spare, spare[0]
        else:
            self._points = None

    def reset(self) -> None:
        """Forget the predictor, the gate and the points (placement and settings are kept)."""
        self._lib.refresh_reset(self._ptr)
        self._points = None
        self._live = self._spare = (None, 0)

    def horizon(self, tick: int) -> np.ndarray | None:
        """r_{tick+1} … r_{tick+N}, or None before the first valid sample (a read-only view)."""
        points = self.horizons(tick, 1)
        return None if points is None else points[0]

    def horizons(self, tick: int, count: int) -> np.ndarray | None:
        """:meth:`horizon` of ticks tick … tick + count − 1 as one read-only (count, N, d)
        array (:func:`~rhmpc.control.reference.windows`), or None before the first sample."""
        points = self._points
        if points is None:
            return None
        return windows(points, tick + 1 - self._public.first, count, self.N)

    def adopt(self, live: np.ndarray, spare: np.ndarray) -> None:
        """From now on the points are ``live``'s (written by C elsewhere, e.g. the compiled
        slices), and ``spare`` takes the next refresh's turn."""
        self._live, self._spare = (live, live.ctypes.data), (spare, spare.ctypes.data)
        self._points = live

    def slices(self, hold: np.ndarray):
        """The slices of a chunk run from compiled control ticks
        (:class:`~rhmpc.control.compiled_slices.CompiledSlices`), with ``hold`` (N, 3) the
        points before the first sample [m]."""
        from rhmpc.control.compiled_slices import CompiledSlices

        return CompiledSlices(self, hold)

    # -- state ---------------------------------------------------------------------------
    @staticmethod
    def update_error(code: int, stamp: float) -> str:
        """The one-line error of ``refresh_update``'s (negative) code."""
        return {-1: "the sample's size is not 1 … 3 before the predictor knows its dimension",
                -3: f"the sample's time stamp must be finite, got {stamp!r}"}.get(
                    code, f"refresh_update failed ({code})")

    @property
    def failure(self) -> str | None:
        """Why a forecast failed (until :meth:`reset`), or None."""
        return {0: None, 1: "the compiled refresh could not grow its forecast arrays",
                2: "the latency asks for a forecast of a million points or more"
                }[self._public.failed]

    @property
    def locked(self) -> bool:
        """True while the outlier gate rejects samples outside it (False without a gate)."""
        return bool(self._public.locked)

    @property
    def age_sum(self) -> float:
        return self._public.age_sum

    @property
    def age_count(self) -> int:
        return self._public.age_count

    @property
    def mean_age(self) -> float:
        """Mean age of the newest sample when a forecast is made from it [s] (NaN if none)."""
        count = self._public.age_count
        return self._public.age_sum / count if count else math.nan

    def _error_rms(self) -> np.ndarray:
        K = self._lib.refresh_error_rms(self._ptr, self._rms.ctypes.data, self._rms.shape[0])
        if K > self._rms.shape[0]:
            self._rms = np.empty(K)
            K = self._lib.refresh_error_rms(self._ptr, self._rms.ctypes.data, K)
        return self._rms[:K].copy()


def _config(reference: PredictedReference, dim: int | None) -> _Config:
    """The C configuration of the reference, its predictor and its gate."""
    predictor, gate = reference.predictor, reference.gate
    s = predictor.settings
    generalized = type(predictor) is GeneralizedRLS
    delta = float(s.delta / predictor.unit**2)  # predictors.rls_one_step.make_rls
    c = _Config(
        generalized=generalized, order=s.order, points=s.points if generalized else 1,
        correlated=bool(s.correlated), hold_init=s.init == "hold", dim=s.dim or 0,
        dcap=s.dim or dim or MAX_DIM,
        envelope_block=max(1, round(predictor.RANGE_SECONDS / 8 / predictor.dt)),
        forgetting=float(s.forgetting_factor), delta=delta,
        p_max=float(s.p_max_factor) / delta, guard_multiple=predictor.GUARD_MULTIPLE,
        error_memory=max(1.0, float(predictor.ERROR_MEMORY_SECONDS / predictor.dt)),
        Ts=reference.Ts, dt=reference.dt, horizon=reference.N,
        prediction_points=reference.prediction_points, span=reference._span,
        kcap=reference.prediction_points + K_MARGIN, guard_speed=reference.guard_speed,
        guard_margin=reference.guard_margin, gate=gate is not None, gate_floor=math.nan,
        min_floor=OutlierGate.MIN_FLOOR,
    )
    if gate is not None:
        c.max_rejections, c.relock, c.calibration = gate.max_rejections, gate.relock, \
            gate.calibration
        c.gate_floor = math.nan if gate.gate is None else gate.gate
        c.min_floor = gate.MIN_FLOOR
    return c


#: Methods whose override on a predictor instance the compiled twin would not follow.
_METHODS = frozenset({"update", "predict", "retract", "learn", "score", "reset", "_next",
                      "_predict", "_update", "_missing", "_retract", "_guard", "_allocate"})


def compile_reference(reference: PredictedReference, dim: int | None = None
                      ) -> tuple[CompiledReference | None, str]:
    """The compiled twin of a freshly built Python ``reference``, or None and why.

    Parameters
    ----------
    reference : PredictedReference
        Around a :class:`~predictors.rls_generalized.GeneralizedRLS` or
        :class:`~predictors.rls_one_step.OneStepRLS` (exactly those types) with its unit given,
        not fed yet; its gate, guard, placement and every setting are copied.
    dim : int, optional
        The samples' dimension (1 … 3) where the predictor's ``settings.dim`` is None.

    Returns
    -------
    (CompiledReference or None, str)
        The twin and ``""``, or None and a one-line reason (an unsupported predictor or
        reference, the unit inference, no compiler).
    """
    if type(reference) is not PredictedReference:
        return None, f"{type(reference).__name__} is not a PredictedReference"
    predictor = reference.predictor
    if type(predictor) not in (GeneralizedRLS, OneStepRLS):
        return None, (f"{type(predictor).__name__} has no compiled refresh "
                      "(GeneralizedRLS and OneStepRLS have)")
    s = predictor.settings
    if s.unit is None:
        return None, "unit None: the unit inference runs in Python"
    if predictor.n:
        return None, "the reference has been fed: compile a fresh one"
    if _METHODS & set(vars(predictor)):
        return None, f"the predictor overrides {', '.join(sorted(_METHODS & set(vars(predictor))))}"
    if reference.monitor is not None:
        return None, "a heart-rate monitor is attached (RLS predictors have no heart rate)"
    if reference.gate is not None and type(reference.gate) is not OutlierGate:
        return None, f"{type(reference.gate).__name__} is not an OutlierGate"
    d = s.dim or dim
    if s.dim is not None and dim is not None and dim != s.dim:
        return None, f"dim={dim} but the predictor's settings.dim={s.dim}"
    if d is not None and not 1 <= d <= MAX_DIM:
        return None, f"d={d}: the compiled refresh takes 1 … {MAX_DIM} axes"
    library = load_library()
    if library is None:
        return None, unavailable_reason or "the compiled refresh is not available"
    return CompiledReference(library, reference, dim), ""

