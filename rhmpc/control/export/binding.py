"""The exported controller in a Python loop: :class:`CController`, the two calls of ``rhmpc.h``.

``rhmpc simulate --controller c`` runs the C that ``rhmpc export`` writes in place of the whole
Python controller: the library is built once per distinct export (:func:`controller_in_c`, with
the one build helper :mod:`rhmpc.compiled`) and called through :mod:`ctypes`. Its durations are
the C's own (``clock_gettime`` inside ``rhmpc_refresh`` and ``rhmpc_step``). The library's OSQP
workspace is a set of static globals, so one library image holds one controller; a second live
:class:`CController` on the same file loads a private copy of it.
"""

from __future__ import annotations

import ctypes
import shutil
import tempfile
import weakref
from collections import Counter
from pathlib import Path

import numpy as np

from rhmpc.compiled import build, compiler
from rhmpc.control.fallback import MPCStats

from .generate import ExportError, _generate_into
from .layout import COUNTS, SOURCES, STATUS_NAMES, public_struct

_in_use: dict[str, weakref.ref] = {}


class ToolchainError(OSError):
    """No C compiler, or the build failed (the message says which, in one line)."""


def missing_toolchain() -> str | None:
    """None if a C compiler is on the PATH, else a one-line reason."""
    return None if compiler() else "the C controller needs a C compiler (cc or gcc; or $CC)"


_DIMS = ("N", "NX", "NU", "NY", "NV", "M", "NPAR", "NZ", "NEXTRA", "D", "SPAN", "N_STATUS",
         "N_SOURCES", "N_COUNTS")


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
    vp, ll, d = ctypes.c_void_p, ctypes.c_longlong, ctypes.c_double
    for name, args, result in (("rhmpc_init", (vp,), None), ("rhmpc_place", (vp, vp, vp), None),
                               ("rhmpc_refresh", (vp, ll, d, vp), ctypes.c_int),
                               ("rhmpc_step", (vp, ll, vp, vp), ctypes.c_int),
                               ("rhmpc_forecast", (vp, ll, d, vp, ctypes.c_int), ctypes.c_int),
                               ("rhmpc_force_failures", (vp, ll), None),
                               ("rhmpc_sizeof", (), ll), ("rhmpc_public_sizeof", (), ll),
                               ("rhmpc_dims", (vp,), None)):
        getattr(lib, name).argtypes, getattr(lib, name).restype = args, result
    return path, lib, private


class CController:
    """The exported controller behind the calls of :class:`rhmpc.control.controller.Controller`.

    Parameters
    ----------
    library : path
        The shared library built from an export (:func:`controller_in_c`).
    mpc : RecedingHorizonMPC
        The Python MPC it was generated from (its gain tick is the timing yardstick).
    """

    def __init__(self, library: str | Path, mpc) -> None:
        path, lib, self._private = _load(str(Path(library).resolve()))
        _in_use[path] = weakref.ref(self)
        self.library, self._lib, self.mpc = path, lib, mpc
        raw = np.zeros(len(_DIMS), dtype=np.intc)
        lib.rhmpc_dims(raw.ctypes.data)
        self.dims = dict(zip(_DIMS, (int(v) for v in raw), strict=True))
        self.N, self.nu, self.span = self.dims["N"], self.dims["NU"], self.dims["SPAN"]
        public = public_struct(self.dims)
        if ctypes.sizeof(public) != lib.rhmpc_public_sizeof():
            raise ToolchainError(f"library {path}: rhmpc_public_t does not match the binding")
        self._state = np.zeros(int(lib.rhmpc_sizeof()) // 8 + 2)  # 8-byte aligned
        self._addr = self._state.ctypes.data
        self._pub = public.from_address(self._addr)
        self._points = np.ctypeslib.as_array(self._pub.points).reshape(self.span, 3)
        self._points.flags.writeable = False
        self._q, self._tau, self._z = np.zeros(self.nu), np.zeros(self.nu), np.zeros(3)
        self.torque_limit = np.ctypeslib.as_array(
            (ctypes.c_double * self.nu).in_dll(lib, "rhmpc_tau_max")).copy()
        self._origin, self._center = np.zeros(3), np.zeros(3)
        self.reset()

    def reset(self) -> None:
        """At rest at the home posture: no plan, no points, zero counters (placed as before)."""
        self._lib.rhmpc_init(self._addr)
        self.place(self._origin, self._center)

    def place(self, origin, center=(0.0, 0.0, 0.0)) -> None:
        """Where the motion sits in the workspace [m]: the sensor's point ``center`` at
        ``origin`` (``rhmpc_place``; :meth:`PredictedReference.place`)."""
        self._origin = np.array(origin, dtype=float).reshape(3)
        self._center = np.array(center, dtype=float).reshape(3)
        self._lib.rhmpc_place(self._addr, self._origin.ctypes.data, self._center.ctypes.data)

    def refresh(self, tick: int, z: np.ndarray | None, stamp: float,
                others: np.ndarray | None = None) -> None:
        """``rhmpc_refresh``: a sample ``z`` (3,) [m] measured at ``stamp`` [s], or None."""
        if z is None:
            status = self._lib.rhmpc_refresh(self._addr, tick, stamp, None)
        else:
            self._z[:] = z
            status = self._lib.rhmpc_refresh(self._addr, tick, stamp, self._z.ctypes.data)
        if status != 0:
            raise ValueError(f"rhmpc_refresh: the stamp {stamp!r} is not a finite time")

    def forecast(self, tick: int, stamp: float, points: np.ndarray) -> bool:
        """``rhmpc_forecast``: forecast points (K, 3) [m] made outside, the first at ``stamp``
        [s]; whether they were taken."""
        nodes = np.ascontiguousarray(points, dtype=float)
        count = nodes.shape[0] if nodes.ndim == 2 and nodes.shape[1] == 3 else 0
        return self._lib.rhmpc_forecast(self._addr, tick, stamp, nodes.ctypes.data, count) == 0

    def step(self, tick: int, q: np.ndarray) -> np.ndarray:
        """``rhmpc_step``: the torques τ [N·m] from the encoders' angles ``q`` [rad]."""
        self._q[:] = q
        self._lib.rhmpc_step(self._addr, tick, self._q.ctypes.data, self._tau.ctypes.data)
        return self._tau.copy()

    def horizon(self, tick: int) -> np.ndarray:
        """The points r_{tick+1..tick+N} the step of ``tick`` tracks (a read-only view)."""
        start = min(max(tick + 1 - self._pub.first, 0), self.span - self.N)
        return self._points[start : start + self.N]

    def force_failures(self, count: int = 1) -> None:
        """Make the next ``count`` solves report ``"injected"`` (the solve still runs)."""
        if count < 0:
            raise ValueError(f"count must be >= 0, got {count}")
        self._lib.rhmpc_force_failures(self._addr, int(count))

    def _vector(self, name: str) -> np.ndarray:
        return np.array(getattr(self._pub, name))

    u = property(lambda self: self._vector("u"), doc="The last MPC torque [N·m].")
    tau_command = property(lambda self: self._vector("tau_command"),
                           doc="The last torque before the clip [N·m].")
    x_hat = property(lambda self: self._vector("x_hat"), doc="The last state estimate.")
    saturated = property(lambda self: bool(self._pub.saturated))
    step_ns = property(lambda self: int(self._pub.step_ns), doc="The last step's time [ns].")
    refresh_ns = property(lambda self: int(self._pub.refresh_ns),
                          doc="The last refresh's time [ns].")

    @property
    def predictor_counts(self) -> Counter:
        """The reference's events, with the Python predictor's names."""
        return Counter({name: int(n) for name, n in zip(COUNTS, self._pub.counts,
                                                        strict=True) if n})

    @property
    def outliers(self) -> tuple[int, int]:
        """(samples the gate rejected, samples retracted after the fact) so far."""
        counts = self._pub.counts
        return int(counts[COUNTS.index("outliers_rejected")]), int(
            counts[COUNTS.index("retracted")])

    @property
    def gate_floor(self) -> float | None:
        floor = float(self._pub.gate_floor)
        return None if not np.isfinite(floor) else floor

    @property
    def encoder_counts(self) -> dict:
        """The observer's events: ``held`` (readings held out), ``reacquired``."""
        return {"held": int(self._pub.encoder_held),
                "reacquired": int(self._pub.encoder_reacquired)}

    @property
    def mean_age(self) -> float:
        count = self._pub.age_count
        return self._pub.age_sum / count if count else float("nan")

    @property
    def stats(self) -> MPCStats:
        """The counters in the form of :class:`MPCStats` (``parts_ns[0]`` = the C step)."""
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


def build_library(controller, robot: str) -> Path:
    """Export ``controller`` and build its shared library, once per distinct export (the cache
    of :mod:`rhmpc.compiled`); raises :class:`ToolchainError` or :class:`ExportError`."""
    with tempfile.TemporaryDirectory(prefix="rhmpc-export-") as tmp:
        out = Path(tmp)
        _generate_into(controller, robot, out)
        sources = [out / n for n in ("rhmpc.c", "rhmpc_mpc.c", "rhmpc_reference.c",
                                     "rhmpc_model.c", "rhmpc_data.c",
                                     "osqp/rhmpc_osqp_workspace.c")]
        sources += sorted((out / "osqp" / "src").glob("*.c"))
        include = (out, out / "osqp", out / "osqp" / "inc" / "public",
                   out / "osqp" / "inc" / "private")
        library, reason = build(sources, "rhmpc-controller", include)
    if library is None:
        raise ToolchainError(reason)
    return library


def controller_in_c(controller, robot: str) -> CController:
    """The C of ``controller`` (a :class:`~rhmpc.control.controller.Controller` whose reference
    is placed), built and loaded, placed where the Python one is."""
    try:
        library = build_library(controller, robot)
    except ExportError as exc:
        raise ExportError(f"--controller c: {exc}") from None
    c = CController(library, controller.mpc)
    c.place(controller.reference.origin, controller.reference.center)
    return c
