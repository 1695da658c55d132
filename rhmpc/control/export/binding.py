"""The controller's library in Python: :class:`Controller`, the calls of ``rhmpc.h`` through
:mod:`ctypes`.

The library is the C that ``rhmpc export`` writes, generated from the controller's description
(its MPC's QP, its observer's gains, its model, its reference's settings) and built once per
distinct export by the one build helper :mod:`rhmpc.compiled` (the cache's key covers the
generated sources, so an edit of a template, of the generator or of a setting rebuilds it).
Every tick runs there; Python keeps what a researcher edits: the formulation, the settings, and
the predictors of :mod:`rhmpc.predictors`, whose forecasts enter the library through its
forecast entry (:class:`rhmpc.control.reference.PredictedReference`). The library's OSQP
workspace is a set of static globals, so one library image holds one controller; a second live
:class:`Controller` on the same file loads a private copy of it.
"""

from __future__ import annotations

import ctypes
import math
import shutil
import tempfile
import time
import weakref
from pathlib import Path

import numpy as np

from rhmpc.compiled import build, compiler, remember, remembered

from .generate import ExportError, _generate_into, description_key
from .layout import COUNTS, RETRACT, SOURCES, STATUS_NAMES, MPCStats, public_struct

_in_use: dict[str, weakref.ref] = {}
clock = time.perf_counter_ns


class ToolchainError(OSError):
    """No C compiler, or the build failed (the message says which, in one line)."""


def missing_toolchain() -> str | None:
    """None if a C compiler is on the PATH, else a one-line reason."""
    return None if compiler() else "the controller needs a C compiler (cc or gcc; or $CC)"


_DIMS = ("N", "NX", "NU", "NY", "NV", "M", "NPAR", "NZ", "NEXTRA", "D", "SPAN", "N_STATUS",
         "N_SOURCES", "N_COUNTS")
#: The signatures of the library's calls: (name, argument types, result type).
_VP, _LL, _D, _I = ctypes.c_void_p, ctypes.c_longlong, ctypes.c_double, ctypes.c_int
_CALLS = (("rhmpc_init", (_VP,), None), ("rhmpc_place", (_VP, _VP, _VP), None),
          ("rhmpc_refresh", (_VP, _LL, _D, _VP), _I),
          ("rhmpc_step", (_VP, _LL, _VP, _VP), _I),
          ("rhmpc_step_delayed", (_VP, _LL, _LL, _VP, _VP), _I),
          ("rhmpc_mpc", (_VP, _VP, _VP, _VP), _I),
          ("rhmpc_forecast", (_VP, _LL, _D, _VP, _I), _I),
          ("rhmpc_sample", (_VP, _LL, _D, _VP, RETRACT, _VP, _VP), _I),
          ("rhmpc_nodes", (_VP, _VP, _I, _I, _VP), _I),
          ("rhmpc_node_values", (_VP,), ctypes.POINTER(_D)),
          ("rhmpc_interpolate", (_VP, _LL), _I), ("rhmpc_points", (_VP, _LL, _VP, _I), None),
          ("rhmpc_force_failures", (_VP, _LL), None), ("rhmpc_take_over", (_VP, _VP), None),
          ("rhmpc_sizeof", (), _LL), ("rhmpc_public_sizeof", (), _LL),
          ("rhmpc_dims", (_VP,), None))


def _load(path: str) -> tuple[str, ctypes.CDLL, tempfile.TemporaryDirectory | None]:
    """The library at ``path``, or a private copy of it if another live controller uses it."""
    private = None
    other = _in_use.get(path)
    if other is not None and other() is not None:
        private = tempfile.TemporaryDirectory(prefix="rhmpc-c-")
        copy = Path(private.name) / Path(path).name
        shutil.copy2(path, copy)
        path = str(copy)
    lib = ctypes.CDLL(path)
    for name, args, result in _CALLS:
        getattr(lib, name).argtypes, getattr(lib, name).restype = args, result
    return path, lib, private


class Controller:
    """Reference, observer, MPC and cancellation behind ``refresh``, ``forecast`` and ``step``:
    the library built from their description (module docstring).

    Parameters
    ----------
    mpc : rhmpc.control.mpc.RecedingHorizonMPC
        The MPC's description: the QP formulated with CasADi, its settings.
    reference : PredictedReference or rhmpc.sim.loop.exact.ExactReference
        The reference (``place`` it before or after).
    observer : rhmpc.control.observer.JointObserver
        The observer's gains and its innovation gate.
    cancellation : rhmpc.control.cancellation.NonlinearityCancellation or None
        The controller's model of ĝ + Ĉq̇ + f̂; None: nothing to cancel (a linear plant).
    torque_limit : ndarray (nu,)
        abs(τ) the actuators apply [N·m].
    input_delay : int
        Ticks from a torque's computation to its action (0: it acts over the next tick).
    internal : bool
        The library's own RLS predictor serves the refreshes (a target with no predictor
        process; the run's predictor must be ``one-step`` or ``generalized``), not the Python
        predictor of the reference.

    Raises
    ------
    ToolchainError
        No C compiler, or the build failed.
    ExportError
        A description the generated code does not reproduce.
    """

    def __init__(self, mpc, reference, observer, cancellation, torque_limit: np.ndarray,
                 input_delay: int = 0, *, internal: bool = False) -> None:
        if isinstance(input_delay, bool) or not isinstance(input_delay, int) or input_delay < 0:
            raise ValueError(f"input_delay must be an integer >= 0 [ticks], got {input_delay!r}")
        self.mpc, self.reference, self.observer = mpc, reference, observer
        self.cancellation, self.input_delay = cancellation, input_delay
        self.torque_limit = np.asarray(torque_limit, dtype=float).copy()
        self.nu, self.N = self.torque_limit.size, mpc.N
        self.internal = bool(internal)
        robot = getattr(getattr(mpc.arm, "robot", None), "name", "arm")
        path, lib, self._private = _load(str(build_library(self, robot, internal=internal)))
        _in_use[path] = weakref.ref(self)
        self.library, self._lib = path, lib
        raw = np.zeros(len(_DIMS), dtype=np.intc)
        lib.rhmpc_dims(raw.ctypes.data)
        self.dims = dict(zip(_DIMS, (int(v) for v in raw), strict=True))
        self.span = self.dims["SPAN"]
        public = public_struct(self.dims)
        if ctypes.sizeof(public) != lib.rhmpc_public_sizeof():
            raise ToolchainError(f"library {path}: rhmpc_public_t does not match the binding")
        self._state = np.zeros(int(lib.rhmpc_sizeof()) // 8 + 2)  # 8-byte aligned
        self._addr = ctypes.c_void_p(self._state.ctypes.data)
        self._pub = pub = public.from_address(self._state.ctypes.data)
        self._points = np.ctypeslib.as_array(pub.points).reshape(self.span, 3)
        self._points.flags.writeable = False
        self.counts_view = np.ctypeslib.as_array(pub.counts)
        self._u, self._tau_c = np.ctypeslib.as_array(pub.u), np.ctypeslib.as_array(pub.tau_command)
        self._x_hat = np.ctypeslib.as_array(pub.x_hat)
        self._q, self._tau, self._z = np.zeros(self.nu), np.zeros(self.nu), np.zeros(3)
        self._q_at, self._tau_at, self._z_at = (ctypes.c_void_p(a.ctypes.data) for a in (
            self._q, self._tau, self._z))
        self._step, self._refresh = lib.rhmpc_step, lib.rhmpc_refresh
        self._exact = getattr(reference, "predictor", False) is None
        self._refresh_ns = 0
        reference.bind(self)
        self.reset()

    def reset(self) -> None:
        """At rest at the home posture: no plan, no points, zero counters (placed as before)."""
        self._lib.rhmpc_init(self._addr)
        self._covered = -1  # the last tick whose exact point the library holds
        self.reference.reset()
        self.place(self.reference.origin, self.reference.center)

    def place(self, origin, center=(0.0, 0.0, 0.0)) -> None:
        """The sensor's point ``center`` sits at ``origin`` [m] (``rhmpc_place``)."""
        o, c = (np.array(v, dtype=float).reshape(3) for v in (origin, center))
        self._lib.rhmpc_place(self._addr, o.ctypes.data, c.ctypes.data)

    def refresh(self, tick: int, z: np.ndarray | None, stamp: float,
                others: np.ndarray | None = None) -> None:
        """A sensor sample's arrival on ``tick``: ``z`` measured at ``stamp`` [s] (None: no new
        sample), ``others`` the other tracked points' samples: the reference's gate, its
        predictor's update and forecast, the interpolation, the guard."""
        if self._exact:
            return
        if self.internal:
            status = self._refresh(self._addr, tick, stamp, self._sample(z))
            if status != 0:
                raise ValueError(f"rhmpc_refresh: the stamp {stamp!r} is not a finite time")
            self._refresh_ns = self._pub.refresh_ns  # inside C
            return
        start = clock()
        self.reference.refresh(tick, z, stamp, others)
        self._refresh_ns = clock() - start  # the predictor's Python included

    def forecast(self, tick: int, stamp: float, points: np.ndarray) -> bool:
        """A forecast made outside arriving on ``tick``: ``points[k]`` the POI at ``stamp + k·dt``
        [m] in the sensor's frame (``rhmpc_forecast``); whether it was taken."""
        if self._exact or self.internal:
            return self.take_forecast(tick, stamp, points)
        return self.reference.forecast(tick, stamp, points)  # its predictor counts it

    def take_forecast(self, tick: int, stamp: float, points: np.ndarray) -> bool:
        """``rhmpc_forecast`` itself: whether the library took the points."""
        nodes = np.ascontiguousarray(points, dtype=float)
        count = nodes.shape[0] if nodes.ndim == 2 and nodes.shape[1] == 3 else 0
        taken = self._lib.rhmpc_forecast(self._addr, tick, stamp, nodes.ctypes.data, count) == 0
        self._refresh_ns = self._pub.refresh_ns
        return taken

    def _sample(self, z) -> int | None:
        """The address of ``z`` (3,) copied into the binding's buffer, or None."""
        if z is None:
            return None
        self._z[:] = z
        return self._z_at

    def step(self, tick: int, q: np.ndarray, delay: int = 0) -> np.ndarray:
        """One control tick from the encoders' joint angles ``q`` [rad] of tick
        ``tick − delay``: the torque τ [N·m]. A late reading is fused into its own tick and
        carried forward (``rhmpc_step_delayed``; :mod:`rhmpc.control.observer`)."""
        if self._exact and tick + self.N > self._covered:
            self._cover(tick)
        self._q[:] = q
        if delay:
            self._lib.rhmpc_step_delayed(self._addr, tick, delay, self._q_at, self._tau_at)
        else:
            self._step(self._addr, tick, self._q_at, self._tau_at)
        return self._tau.copy()

    def library_loop(self) -> dict[str, int]:
        """The library's calls and the public fields a loop in C records, as addresses:
        ``step`` (``rhmpc_step``), ``horizon`` (``rhmpc_horizon``), ``ctl``, ``u``,
        ``tau_command``, ``step_ns``. A loop in C steps the library directly on the ticks up to
        :meth:`steps_alone` (the simulated plant's, :meth:`rhmpc.sim.plant.kernel.Drive.run`)."""
        base, public = ctypes.addressof(self._pub), type(self._pub)
        fields = {name: base + getattr(public, name).offset
                  for name in ("u", "tau_command", "step_ns")}
        calls = {name: ctypes.cast(getattr(self._lib, f"rhmpc_{name}"), ctypes.c_void_p).value
                 for name in ("step", "horizon")}
        return {**calls, "ctl": self._addr.value, **fields}

    def steps_alone(self) -> float:
        """The last tick :meth:`step` needs nothing of Python for: with the exact reference, the
        last whose horizon the library holds; else every tick (inf)."""
        return self._covered - self.N if self._exact else math.inf

    def mpc_step(self, x: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """The MPC alone (``rhmpc_mpc``): τ_mpc [N·m] for the state ``x`` = [q − q0; q̇] (nx,)
        and the points ``ref`` (N, 3) [m], with the counters and the plan of a step."""
        x = np.ascontiguousarray(x, dtype=float)
        ref = np.ascontiguousarray(ref, dtype=float)
        if x.shape != (2 * self.nu,) or ref.shape != (self.N, 3):
            raise ValueError(f"mpc_step expects x ({2 * self.nu},) and ref ({self.N}, 3), got "
                             f"{x.shape}, {ref.shape}")
        self._lib.rhmpc_mpc(self._addr, x.ctypes.data, ref.ctypes.data, self._tau_at)
        return self._tau.copy()

    def _cover(self, tick: int) -> None:
        """Give the library the exact reference's points of the ticks after ``tick``."""
        points = np.ascontiguousarray(self.reference.points(tick + 1, self.span))
        self._lib.rhmpc_points(self._addr, tick, points.ctypes.data, points.shape[0])
        self._covered = tick + points.shape[0]

    def horizon(self, tick: int) -> np.ndarray:
        """The points r_{tick+1..tick+N} the step of ``tick`` tracks (a read-only view)."""
        start = min(max(tick + 1 - self._pub.first, 0), self.span - self.N)
        return self._points[start : start + self.N]

    def take_over(self, u: np.ndarray) -> None:
        """The torque ``u`` [N·m] that acted last (another controller's): u_{−1} of the next
        QP, for a bumpless start (``rhmpc_take_over``; clipped to ±u_max)."""
        u = np.ascontiguousarray(u, dtype=float).reshape(self.nu)
        self._lib.rhmpc_take_over(self._addr, u.ctypes.data)

    def force_failures(self, count: int = 1) -> None:
        """Make the next ``count`` solves report ``"injected"`` (the solve still runs)."""
        if count < 0:
            raise ValueError(f"count must be >= 0, got {count}")
        self._lib.rhmpc_force_failures(self._addr, int(count))

    u = property(lambda self: self._u.copy(), doc="The last MPC torque u [N·m].")
    tau_command = property(lambda self: self._tau_c.copy(),
                           doc="The last commanded torque τ_c, before the clip [N·m].")
    x_hat = property(lambda self: self._x_hat.copy(),
                     doc="The last step's state estimate [q − q0; q̇].")
    tau = property(lambda self: np.array(self._pub.tau), doc="The last torque applied [N·m].")
    saturated = property(lambda self: bool(self._pub.saturated),
                         doc="Whether the last step's τ_c was clipped.")
    step_ns = property(lambda self: int(self._pub.step_ns),
                       doc="The last step's time inside the library [ns].")
    refresh_ns = property(lambda self: self._refresh_ns,
                          doc="The last refresh's or forecast's time [ns].")

    def count(self, name: str) -> int:
        """The library's count of the reference's event ``name`` (:data:`layout.COUNTS`)."""
        return int(self.counts_view[COUNTS.index(name)])

    @property
    def predictor_counts(self) -> dict:
        """The predictor's and the gate's event counts (empty without a predictor)."""
        if self._exact:
            return {}
        if self.internal:
            return {n: int(v) for n, v in zip(COUNTS, self.counts_view, strict=True) if v}
        return dict(self.reference.predictor.counts)

    @property
    def outliers(self) -> tuple[int, int]:
        """(samples the gate rejected, samples retracted after the fact) so far."""
        counts = self.predictor_counts
        return counts.get("outliers_rejected", 0), counts.get("retracted", 0)

    @property
    def gate_floor(self) -> float | None:
        """The outlier gate's floor [m] (None without a gate, or while it calibrates)."""
        floor = float(self._pub.gate_floor)
        return floor if np.isfinite(floor) and not self._exact else None

    @property
    def encoder_counts(self) -> dict:
        """The observer's events: ``held`` (readings held out), ``reacquired``."""
        return {"held": int(self._pub.encoder_held),
                "reacquired": int(self._pub.encoder_reacquired)}

    @property
    def mean_age(self) -> float:
        """Mean age of the newest sample when a forecast is made from it [s] (NaN if none)."""
        count = self._pub.age_count
        return self._pub.age_sum / count if count else float("nan")

    @property
    def stats(self) -> MPCStats:
        """The MPC's counters (``parts_ns[0]``: the whole step inside the library)."""
        pub = self._pub
        ticks = int(pub.ticks)
        return MPCStats(
            ticks=ticks, status=STATUS_NAMES[pub.status] if ticks else "none",
            source=SOURCES[pub.source] if ticks else "none",
            iterations=int(pub.iterations), screened=int(pub.screened), boxed=int(pub.boxed),
            level=int(pub.level), box_iterations=int(pub.box_iterations), solve_time=0.0,
            parts_ns=[int(pub.step_ns), 0, 0, 0],
            failures={STATUS_NAMES[i]: int(n) for i, n in enumerate(pub.failures) if n},
            fallbacks={name: int(pub.fallbacks[SOURCES.index(name)])
                       for name in MPCStats().fallbacks},
        )


def build_library(controller, robot: str, internal: bool = False) -> Path:
    """Generate ``controller``'s C and build its shared library, once per distinct export (the
    cache of :mod:`rhmpc.compiled`; a description built before is not generated again: its
    :func:`~rhmpc.control.export.generate.description_key`); raises :class:`ToolchainError` or
    :class:`ExportError`. ``internal``: the library must run the reference's RLS predictor."""
    try:
        key = description_key(controller, robot, internal)
    except ExportError as exc:
        raise ExportError(f"the controller: {exc}") from None
    known = remembered("rhmpc-controller", key)
    if known is not None:
        return known
    with tempfile.TemporaryDirectory(prefix="rhmpc-export-") as tmp:
        out = Path(tmp)
        _generate_into(controller, robot, out, internal=internal)
        sources = [out / n for n in ("rhmpc.c", "rhmpc_mpc.c", "rhmpc_reference.c",
                                     "rhmpc_model.c", "rhmpc_data.c",
                                     "osqp/rhmpc_osqp_workspace.c")]
        sources += sorted((out / "osqp" / "src").glob("*.c"))
        include = (out, out / "osqp", out / "osqp" / "inc" / "public",
                   out / "osqp" / "inc" / "private")
        library, reason = build(sources, "rhmpc-controller", include)
    if library is None:
        raise ToolchainError(reason)
    remember("rhmpc-controller", key, library)
    return library
