"""Binding of an exported controller: :class:`CController`, a drop-in for ``mpc.step``.

The library is loaded with ctypes (setup, counters, fault injection); the per-tick call goes
through the ``_rhmpc_step`` extension (:mod:`.extension`), or through ctypes where that cannot
be built. The library's OSQP workspace is a set of static globals, so one library image holds
one controller; a second live :class:`CController` on the same file loads a private copy of it.
"""

from __future__ import annotations

import ctypes
import shutil
import tempfile
import time
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np

from rhmpc.control.mpc import MPCStats

from . import extension
from .build import ToolchainError
from .generate import EXTRA_SOURCES

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


class CompiledTick(NamedTuple):
    """A controller's tick as a C function, for a loop that runs ticks in C
    (:meth:`sim.plant.native.NativeTick.run_ticks`).

    ``int function(void *state, const double *x, const double *ref, const double *u_prev,
    const double *extra, double *u)`` (``rhmpc_tick_ext`` of ``rhmpc.h``) with ``extra`` NULL;
    ``u_prev`` NULL but on a tick after :meth:`CController.take_u_prev` returned an array.
    """

    function: int  #: address of the tick function
    state: int  #: address of the controller's state (``rhmpc_t``)
    output: np.ndarray  #: (nu,) where the tick writes u; the controller's u_{−1} next tick
    take_u_prev: Callable[[], np.ndarray | None]  #: :meth:`CController.take_u_prev`
    dims: tuple[int, int, int, int]  #: (N, nx, nu, ny): what the tick reads and writes

#: The binding's implementations of ``step``: ``"auto"`` is the extension where it builds.
BINDINGS = ("auto", "extension", "ctypes")


class _CtypesStep:
    """``step`` in Python over ctypes: the fallback where the extension cannot be built.

    Same constructor and attributes as ``_rhmpc_step.Step`` (see ``rhmpc_step.c``).
    """

    def __init__(self, tick, ctl, keep, dims, last, u_in, extra, extra_inputs=None) -> None:
        vp = ctypes.c_void_p
        # PYFUNCTYPE holds the GIL during the call, as the extension does: the library's OSQP
        # workspace is static and must not be entered from two threads at once.
        self._tick = ctypes.PYFUNCTYPE(ctypes.c_int, vp, vp, vp, vp, vp, vp)(tick)
        self._ctl, self._keep = ctl, keep
        N, nx, _, ny, _ = dims
        self._x, self._ref = np.zeros(nx), np.zeros((N, ny))
        self._last, self._extra, self._extra_inputs = last, extra, extra_inputs
        self._ptr = [a.ctypes.data for a in (self._x, self._ref, u_in, extra, last)]
        self.u_pending = 0
        self.call_ns = 0

    def step(self, x: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """τ_mpc (nu,) for ``x`` (nx,) and ``ref`` (N, ny), a new array (as ``Step.step``)."""
        t0 = time.perf_counter_ns()
        x = np.asarray(x, dtype=float)
        ref = np.asarray(ref, dtype=float)
        if x.shape != self._x.shape or ref.shape != self._ref.shape:
            raise ValueError(f"step expects x {self._x.shape} and ref {self._ref.shape}, "
                             f"got {x.shape}, {ref.shape}")
        self._x[:] = x
        self._ref[...] = ref
        px, pr, pu, pe, pt = self._ptr
        if self._extra_inputs is not None and np.isfinite(x).all():
            self._extra[:] = self._extra_inputs(x)
        u_in = pu if self.u_pending else None
        self.u_pending = 0
        self._tick(self._ctl, px, pr, u_in, pe if self._extra_inputs is not None else None, pt)
        self.call_ns = time.perf_counter_ns() - t0
        return self._last.copy()


def _step_type(binding: str) -> tuple[type, str | None]:
    """The implementation of ``step`` for ``binding`` and why it is ctypes under ``"auto"``."""
    if binding not in BINDINGS:
        raise ValueError(f"binding must be one of {BINDINGS}, got {binding!r}")
    if binding == "ctypes":
        return _CtypesStep, None
    module, reason = extension.load()
    if module is not None:
        return module.Step, None
    if binding == "extension":
        raise ToolchainError(f"the compiled binding is unavailable: {reason}")
    return _CtypesStep, reason


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
    vp, ll = ctypes.c_void_p, ctypes.c_longlong
    lib.rhmpc_init.argtypes = (vp,)
    lib.rhmpc_init.restype = None
    lib.rhmpc_force_failures.argtypes = (vp, ll)
    lib.rhmpc_force_failures.restype = None
    lib.rhmpc_sizeof.restype = ll
    lib.rhmpc_dims.argtypes = (vp,)
    lib.rhmpc_dims.restype = None
    return path, lib, private


class CController:
    """The compiled controller behind the ``RecedingHorizonMPC.step`` contract.

    ``step`` is the compiled binding's own (``_rhmpc_step``, :mod:`.extension`): argument
    conversion, shape checks, u_{−1}, the tick and the output array in one C call, no Python
    frame; the output offset's forward kinematics runs inside the tick, in C.

    Measured overhead (PHANToM, default settings; Python 3.11, gcc, a 2-core host shared with
    other jobs): ``step()`` timed from Python with ``time.perf_counter_ns`` around each call,
    minus the tick's own ``tick_ns``, over 19 000 ticks of the bench trajectory (heart-like
    motion, 2-mm jumps), GC off, five runs. The compiled binding adds 0.30–0.32 µs p50 and
    0.5–0.8 µs p99 to the tick (the timer pair itself is 0.07 µs of that; the new output array
    0.08 µs); the ctypes fallback 2.0–2.1 µs p50 and 2.5–4.3 µs p99; a ctypes wrapper that
    evaluates the offset with Pinocchio in Python, 6.9–7.1 µs p50 and 15–19 µs p99.

    Where the extension cannot be built the same ``step`` runs in Python over ctypes
    (:attr:`binding` says which, :attr:`binding_note` why).

    Parameters
    ----------
    library : path
        The shared library built from an export (:func:`~.build.build_cached`).
    dims : tuple[int, int, int, int] | None
        Expected (N, nx, nu, ny), checked against the library's.
    extra_inputs : callable | None
        ``extra_inputs(x) -> (n_extra,)``: the per-tick inputs of the QP after u_{−1}, evaluated
        in Python before each finite-state tick. Needed only if the library does not compute
        them itself (:attr:`extra_source` ``"caller"``); given, it replaces the library's own.
    binding : {"auto", "extension", "ctypes"}
        ``"auto"``: the extension, else ctypes. ``"extension"`` raises
        :class:`~.build.ToolchainError` if it cannot be built.

    Attributes
    ----------
    binding : str
        ``"extension"`` or ``"ctypes"``.
    binding_note : str | None
        Why ``"auto"`` fell back to ctypes (one line), else None.
    extra_source : str
        Where the extra per-tick inputs come from: ``"zero"``, ``"fk"`` (in C), ``"caller"``
        (the library's setting) or ``"python"`` (``extra_inputs``).
    call_ns : int
        Duration of the last ``step`` inside the binding, the tick included [ns].
    """

    def __init__(
        self,
        library: str | Path,
        dims: tuple[int, int, int, int] | None = None,
        extra_inputs: Callable[[np.ndarray], np.ndarray] | None = None,
        binding: str = "auto",
    ) -> None:
        step_type, self.binding_note = _step_type(binding)
        path, lib, self._private = _load(str(Path(library).resolve()))
        _in_use[path] = weakref.ref(self)
        self.library, self._lib = path, lib
        self._read_dims(dims)
        extra_inputs = self._extra_inputs(extra_inputs)
        self.u_max = np.ctypeslib.as_array(
            (ctypes.c_double * self.nu).in_dll(lib, "rhmpc_u_max")).copy()
        self.u_max.setflags(write=False)
        size = int(lib.rhmpc_sizeof())
        self._state = np.zeros(size // 8 + 2, dtype=np.float64)  # 8-byte aligned
        self._addr = self._state.ctypes.data
        self._pub = _Public.from_address(self._addr)
        self._u_in, self._tau = np.zeros(self.nu), np.zeros(self.nu)
        tick = self._tick_address = ctypes.cast(lib.rhmpc_tick_ext, ctypes.c_void_p).value
        self._core = step_type(tick, self._addr, (self._state, lib),
                               (self.N, self.nx, self.nu, self.ny, self.n_extra), self._tau,
                               self._u_in, np.zeros(self.n_extra), extra_inputs)
        self.binding = "ctypes" if step_type is _CtypesStep else "extension"
        self.step = self._core.step  # the binding's own: no Python frame per tick
        self.reset()

    def _read_dims(self, expected: tuple[int, int, int, int] | None) -> None:
        d = np.zeros(9, dtype=np.intc)
        self._lib.rhmpc_dims(d.ctypes.data)
        self.N, self.nx, self.nu, self.ny, self.nv, self.m, self.npar, self.nz, self.n_extra = (
            int(v) for v in d)
        if expected is not None and tuple(expected) != (self.N, self.nx, self.nu, self.ny):
            raise ValueError(f"library {self.library} is for (N, nx, nu, ny) = "
                             f"{(self.N, self.nx, self.nu, self.ny)}, expected {tuple(expected)}")

    def _extra_inputs(self, given: Callable | None) -> Callable | None:
        """The callable the binding evaluates per tick (None: the library's own inputs); sets
        :attr:`extra_source`."""
        source = getattr(self._lib, "rhmpc_extra_source", None)
        source = EXTRA_SOURCES[source()] if source is not None else "caller"
        if self.n_extra and given is None and source == "caller":
            raise ValueError(f"library {self.library} takes {self.n_extra} extra per-tick "
                             "inputs; give extra_inputs")
        given = given if self.n_extra else None
        self.extra_source = "python" if given is not None else source
        return given

    def reset(self, u_prev: np.ndarray | None = None) -> None:
        """Forget the plan and warm start, zero the counters, u_{−1} = ``u_prev`` (default 0)."""
        self._lib.rhmpc_init(self._addr)
        self._tau[:] = 0.0
        self._core.u_pending = 0
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
        if self._core.u_pending:
            return np.clip(self._u_in, -self.u_max, self.u_max)
        return self._tau.copy()

    @u_prev.setter
    def u_prev(self, value: np.ndarray) -> None:
        value = np.asarray(value, dtype=float)
        if value.shape != (self.nu,) or not np.all(np.isfinite(value)):
            raise ValueError(f"u_prev must be {self.nu} finite torques [N·m], got {value!r}")
        self._u_in[:] = value
        self._core.u_pending = 1

    def take_u_prev(self) -> np.ndarray | None:
        """The u_{−1} assigned for the next tick (:attr:`u_prev`, :meth:`reset`), handed over
        once to a caller that runs the tick itself (:attr:`compiled_tick`); None if none."""
        if not self._core.u_pending:
            return None
        self._core.u_pending = 0
        return self._u_in

    @property
    def compiled_tick(self) -> CompiledTick | None:
        """The tick as a C function for a loop in C (:class:`CompiledTick`), or None when its
        extra inputs come from Python (``extra_source == "python"``). Such a loop leaves
        :attr:`call_ns` alone; the counters and :attr:`u_prev` follow its ticks."""
        if self.extra_source == "python":
            return None
        return CompiledTick(self._tick_address, self._addr, self._tau, self.take_u_prev,
                            (self.N, self.nx, self.nu, self.ny))

    def step(self, x: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """One tick in C: τ_mpc (nu,) [N·m] for ``x`` (nx,) and ``ref`` (N, 3), as ``mpc.step``.

        A new array on every call. An instance's ``step`` is its binding's own method (bound in
        ``__init__``); this one documents it and forwards to it.
        """
        return self._core.step(x, ref)

    @property
    def call_ns(self) -> int:
        """Duration of the last ``step`` inside the binding, the tick included [ns]."""
        return int(self._core.call_ns)

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
