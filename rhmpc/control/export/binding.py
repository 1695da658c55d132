"""ctypes binding of an exported controller: :class:`CController`, a drop-in for ``mpc.step``.

The library's OSQP workspace is a set of static globals, so one library image holds one
controller; a second live :class:`CController` on the same file loads a private copy of it.
"""

from __future__ import annotations

import ctypes
import shutil
import tempfile
import time
import weakref
from collections.abc import Callable
from pathlib import Path

import numpy as np

from rhmpc.control.mpc import MPCStats

#: Status names in the order of ``enum rhmpc_status`` (rhmpc.h); 0 = solved.
STATUS_NAMES = (
    "solved", "nonfinite_input", "nonfinite_solution", "solver_error", "injected",
    "solved_inaccurate", "primal_infeasible", "dual_infeasible", "max_iter", "time_limit",
    "non_convex", "interrupted", "unsolved",
)
SOURCE_NAMES = ("qp", "plan", "lq", "brake", "zero")


class _Public(ctypes.Structure):
    """The documented leading fields of ``rhmpc_t``."""

    _fields_ = (
        ("ticks", ctypes.c_longlong),
        ("screened", ctypes.c_longlong),
        ("failures", ctypes.c_longlong * len(STATUS_NAMES)),
        ("fallbacks", ctypes.c_longlong * len(SOURCE_NAMES)),
        ("status", ctypes.c_int),
        ("source", ctypes.c_int),
        ("iterations", ctypes.c_int),
        ("tick_ns", ctypes.c_longlong),
        ("boxed", ctypes.c_longlong),
        ("level", ctypes.c_int),
        ("box_iterations", ctypes.c_int),
    )


_in_use: dict[str, weakref.ref] = {}


class CController:
    """The compiled controller behind the ``RecedingHorizonMPC.step`` contract.

    Parameters
    ----------
    library : path
        The shared library built from an export (:func:`~.build.build_cached`).
    dims : tuple[int, int, int, int] | None
        Expected (N, nx, nu, ny), checked against the library's.
    extra_inputs : callable | None
        ``extra_inputs(x) -> (n_extra,)``: the per-tick inputs of the QP after u_{−1} (the
        controller's output offset), evaluated in Python before each finite-state tick.

    Attributes
    ----------
    tick_ns : int
        Duration of the last tick measured inside C (clock_gettime(CLOCK_MONOTONIC)) [ns].
    call_ns : int
        Duration of the last tick as seen from Python (the ctypes call) [ns].
    """

    def __init__(
        self,
        library: str | Path,
        dims: tuple[int, int, int, int] | None = None,
        extra_inputs: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        path = str(Path(library).resolve())
        other = _in_use.get(path)
        if other is not None and other() is not None:
            self._private = tempfile.TemporaryDirectory(prefix="rhmpc-c-")
            copy = Path(self._private.name) / Path(path).name
            shutil.copy2(path, copy)
            path = str(copy)
        _in_use[path] = weakref.ref(self)
        lib = ctypes.CDLL(path)
        self.library = path
        self._lib = lib
        vp, ll = ctypes.c_void_p, ctypes.c_longlong
        lib.rhmpc_tick_ext.argtypes = (vp, vp, vp, vp, vp, vp)
        lib.rhmpc_tick_ext.restype = ctypes.c_int
        lib.rhmpc_init.argtypes = (vp,)
        lib.rhmpc_init.restype = None
        lib.rhmpc_force_failures.argtypes = (vp, ll)
        lib.rhmpc_force_failures.restype = None
        lib.rhmpc_sizeof.restype = ll
        lib.rhmpc_dims.argtypes = (vp,)
        lib.rhmpc_dims.restype = None
        d = np.zeros(9, dtype=np.intc)
        lib.rhmpc_dims(d.ctypes.data)
        self.N, self.nx, self.nu, self.ny, self.nv, self.m, self.npar, self.nz, self.n_extra = (
            int(v) for v in d)
        if self.n_extra and extra_inputs is None:
            raise ValueError(f"library {path} takes {self.n_extra} extra per-tick inputs; "
                             "give extra_inputs")
        if dims is not None and tuple(dims) != (self.N, self.nx, self.nu, self.ny):
            raise ValueError(f"library {path} is for (N, nx, nu, ny) = "
                             f"{(self.N, self.nx, self.nu, self.ny)}, expected {tuple(dims)}")
        self.u_max = np.ctypeslib.as_array(
            (ctypes.c_double * self.nu).in_dll(lib, "rhmpc_u_max")).copy()
        self.u_max.setflags(write=False)
        size = int(lib.rhmpc_sizeof())
        self._state = np.zeros(size // 8 + 2, dtype=np.float64)  # 8-byte aligned
        self._addr = self._state.ctypes.data
        self._pub = _Public.from_address(self._addr)
        self._x = np.zeros(self.nx)
        self._ref = np.zeros((self.N, self.ny))
        self._u_in = np.zeros(self.nu)
        self._tau = np.zeros(self.nu)
        self._extra = np.zeros(self.n_extra)
        self._extra_inputs = extra_inputs if self.n_extra else None
        self._ptr = [a.ctypes.data for a in (self._x, self._ref, self._u_in, self._tau)]
        self._extra_ptr = self._extra.ctypes.data if self.n_extra else None
        self._u_pending = False
        self._tick = lib.rhmpc_tick_ext
        self.call_ns = 0
        self.reset()

    def reset(self, u_prev: np.ndarray | None = None) -> None:
        """Forget the plan and warm start, zero the counters, u_{−1} = ``u_prev`` (default 0)."""
        self._lib.rhmpc_init(self._addr)
        self._u_pending = False
        if u_prev is not None:
            self.u_prev = u_prev

    def force_failures(self, count: int = 1) -> None:
        """Make the next ``count`` solves report ``"injected"`` (the solve still runs)."""
        if count < 0:
            raise ValueError(f"count must be >= 0, got {count}")
        self._lib.rhmpc_force_failures(self._addr, int(count))

    @property
    def u_prev(self) -> np.ndarray:
        """u_{−1} of the next tick [N·m] (the last returned torque unless assigned)."""
        if self._u_pending:
            return np.clip(self._u_in, -self.u_max, self.u_max)
        return self._tau.copy()

    @u_prev.setter
    def u_prev(self, value: np.ndarray) -> None:
        value = np.asarray(value, dtype=float)
        if value.shape != (self.nu,) or not np.all(np.isfinite(value)):
            raise ValueError(f"u_prev must be {self.nu} finite torques [N·m], got {value!r}")
        self._u_in[:] = value
        self._u_pending = True

    def step(self, x: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """One tick in C: τ_mpc (nu,) [N·m] for ``x`` (nx,) and ``ref`` (N, 3), as ``mpc.step``."""
        x = np.asarray(x, dtype=float)
        ref = np.asarray(ref, dtype=float)
        if x.shape != self._x.shape or ref.shape != self._ref.shape:
            raise ValueError(f"step expects x {self._x.shape} and ref {self._ref.shape}, "
                             f"got {x.shape}, {ref.shape}")
        self._x[:] = x
        self._ref[...] = ref
        if self._extra_inputs is not None and np.isfinite(x).all():
            self._extra[:] = self._extra_inputs(x)  # not timed: the caller's work on a target
        px, pr, pu, pt = self._ptr
        u_in = pu if self._u_pending else None
        self._u_pending = False
        t0 = time.perf_counter_ns()
        self._tick(self._addr, px, pr, u_in, self._extra_ptr, pt)
        self.call_ns = time.perf_counter_ns() - t0
        return self._tau.copy()

    @property
    def tick_ns(self) -> int:
        return int(self._pub.tick_ns)

    @property
    def screened(self) -> int:
        """Ticks solved by screening (OSQP not called) since the last reset."""
        return int(self._pub.screened)

    @property
    def boxed(self) -> int:
        """Ticks solved by level 2 of the screening cascade (the torque-box QP)."""
        return int(self._pub.boxed)

    @property
    def level(self) -> int:
        """Cascade level of the last tick's QP solution (1, 2, 3; 0 = no QP)."""
        return int(self._pub.level)

    @property
    def source(self) -> str:
        """Where the last torque came from: ``"qp"``, ``"plan"``, ``"lq"`` or ``"zero"``."""
        return SOURCE_NAMES[self._pub.source] if self._pub.ticks else "none"

    @property
    def status(self) -> str:
        """Last tick: ``"solved"`` or the reason the QP result was not used."""
        return STATUS_NAMES[self._pub.status] if self._pub.ticks else "none"

    @property
    def stats(self) -> MPCStats:
        """The counters in the form of :class:`MPCStats` (``parts_ns[0]`` = the C tick)."""
        pub = self._pub
        failures = {STATUS_NAMES[i]: int(n) for i, n in enumerate(pub.failures) if n}
        # the sources the Python controller's statistics have (which fallbacks it knows)
        fallbacks = {name: int(pub.fallbacks[SOURCE_NAMES.index(name)])
                     for name in MPCStats().fallbacks}
        return MPCStats(
            ticks=int(pub.ticks), status=self.status, source=self.source,
            iterations=int(pub.iterations), screened=int(pub.screened), boxed=int(pub.boxed),
            level=int(pub.level), box_iterations=int(pub.box_iterations), solve_time=0.0,
            parts_ns=[int(pub.tick_ns), 0, 0, 0], failures=failures, fallbacks=fallbacks,
        )
