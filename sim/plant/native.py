"""The robot's side of the tick compiled: an accelerator, checked against Pinocchio.

Pinocchio is the reference for the plant's dynamics (:class:`~sim.plant.tick.ArmTick`); in the
closed loop its Python tick is mostly argument conversion and interpreter overhead around calls
of about a microsecond of arithmetic each. :class:`NativeTick` runs the same operations in three
C calls a tick, or all the ticks between two refresh slices in one (:meth:`NativeTick.run_ticks`,
with a compiled controller); it is used where it builds (``PlantSettings.dynamics = "auto"``).
Why this and not Pinocchio's own C++, and what it measured: the decision record "The compiled
plant".

``sim/plant/chain.c`` holds Featherstone's articulated-body algorithm, recursive Newton–Euler
and the composite-rigid-body algorithm for a chain of revolute joints, with the parameters read
from the Pinocchio model (joint placements and axes, spatial inertias, rotor armature, gravity)
and the plant's friction ``D q̇ + F_c tanh(q̇/v_s)``. A model with mimic bodies (the PHANToM's
parallelogram) has its forward dynamics as M(q)⁻¹(τ − h), h by recursive Newton–Euler and M by
the composite-rigid-body algorithm, from one set of body poses, with the spatial algebra in its
structured form (a transform as a rotation and a translation, an inertia as a mass, a first
moment and a rotational inertia; Featherstone 2008, §2.8), as Pinocchio computes it. The C
file is compiled with the system's C compiler at first use into a cache directory and loaded
with :mod:`ctypes` (:mod:`sim.compiled`).

Pinocchio stays the reference: ``tests/sim/plant/test_native.py`` compares ABA, RNEA, M and the
end-point with ``pin.aba``, ``pin.rnea``, ``pin.crba`` and the frame placement at random states
(1e-15 relative), on the PHANToM and on a tree of rotated placements and an unaligned axis, and
a whole closed-loop run with both ticks. Where no compiler is found, or the model
has other joints than revolute ones, :func:`load_chain` returns None with the reason
(``unavailable_reason``) and the loop runs on Pinocchio.
"""
from __future__ import annotations

import ctypes
import functools
from pathlib import Path

import numpy as np

from sim.compiled import load

MAX_JOINTS = 8
_SOURCE = Path(__file__).with_name("chain.c")
_AXES = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0),
         "JointModelRZ": (0.0, 0.0, 1.0)}

#: Why the compiled chain is not available (None while it is, or before the first attempt).
unavailable_reason: str | None = None
_library: ctypes.CDLL | None = None
_tried = False

_d, _i = ctypes.c_double, ctypes.c_int


class _Chain(ctypes.Structure):
    """``chain_t`` of sim/plant/chain.c."""

    _fields_ = [
        ("n", _i), ("nb", _i), ("parent", _i * MAX_JOINTS), ("coord", _i * MAX_JOINTS),
        ("scale", _d * MAX_JOINTS), ("offset", _d * MAX_JOINTS), ("projected", _i),
        ("Rp", (_d * 9) * MAX_JOINTS), ("pp", (_d * 3) * MAX_JOINTS),
        ("axis", (_d * 3) * MAX_JOINTS), ("inertia", (_d * 36) * MAX_JOINTS),
        ("armature", _d * MAX_JOINTS), ("motor", _d * (MAX_JOINTS * MAX_JOINTS)),
        ("mapped", _i), ("damping", _d * MAX_JOINTS), ("coulomb", _d * MAX_JOINTS),
        ("inv_stiction", _d), ("gravity", _d * 3),
    ]


def _compile() -> ctypes.CDLL | None:
    """The library, compiled at the first call (once per source version); None if impossible."""
    global _library, _tried, unavailable_reason
    if _tried:
        return _library
    _tried = True
    library, unavailable_reason = load(_SOURCE, "chain")
    if library is None:
        return None
    ptr = ctypes.c_void_p
    signatures = {"chain_aba": [ptr] * 5, "chain_rnea": [ptr] * 5, "chain_mass": [ptr] * 3,
                  "chain_midpoint": [ptr, ptr, ptr, ptr, _d, _i], "hw_integrate": [ptr] * 4,
                  "chain_point": [ptr, ptr, _i, _i, ptr, ptr], "tick_sense": [ptr],
                  "chain_offset": [ptr, ptr, ptr, ptr, ptr, _i, ptr, ptr],
                  "tick_actuate": [ptr], "tick_advance": [ptr]}
    for name, argtypes in signatures.items():
        getattr(library, name).argtypes, getattr(library, name).restype = argtypes, None
    # tick_run calls a compiled controller whose workspace is static: it keeps the GIL, so that
    # no other thread enters the controller meanwhile (rhmpc.control.export.binding)
    library.tick_run_gil = ctypes.PYFUNCTYPE(None, ptr, ptr, _i, _i, ptr, ctypes.c_long, ptr)(
        ctypes.cast(library.tick_run, ptr).value)
    _library = library
    return library


class NativeChain:
    """The compiled dynamics of one Pinocchio model (see :func:`load_chain`)."""

    def __init__(self, library: ctypes.CDLL, chain: _Chain, nv: int) -> None:
        self._lib, self._chain, self.nv = library, chain, nv
        self._ptr = ctypes.addressof(chain)
        # argument buffers with fixed addresses: a call passes integers, not arrays
        self._buf = np.zeros(4 * nv)
        base, step = self._buf.ctypes.data, self._buf.itemsize * nv
        self._q, self._v, self._x, self._out = (self._buf[k * nv : (k + 1) * nv]
                                                for k in range(4))
        self._addr = [base + k * step for k in range(4)]

    def aba(self, q, v, tau) -> np.ndarray:
        """q̈ = ABA(q, q̇, τ) [rad/s²] (no friction: the dynamics alone, as ``pin.aba``)."""
        self._q[:], self._v[:], self._x[:] = q, v, tau
        self._lib.chain_aba(self._ptr, *self._addr)
        return self._out.copy()

    def rnea(self, q, v, a) -> np.ndarray:
        """τ = RNEA(q, q̇, q̈) [N·m] (no friction, as ``pin.rnea``)."""
        self._q[:], self._v[:], self._x[:] = q, v, a
        self._lib.chain_rnea(self._ptr, *self._addr)
        return self._out.copy()

    def mass(self, q) -> np.ndarray:
        """M(q) with the armature [kg·m²] (as ``pin.crba``, both triangles)."""
        self._q[:] = q
        out = np.empty((self.nv, self.nv))
        self._lib.chain_mass(self._ptr, self._addr[0], out.ctypes.data)
        return out

    def midpoint(self, q, v, tau, h: float, substeps: int) -> tuple[np.ndarray, np.ndarray]:
        """(q, q̇) after ``substeps`` explicit-midpoint steps of ``h`` with friction, τ held."""
        self._q[:], self._v[:], self._x[:] = q, v, tau
        a = self._addr
        self._lib.chain_midpoint(self._ptr, a[0], a[1], a[2], h, substeps)
        return self._q.copy(), self._v.copy()

    def points(self, q: np.ndarray, joint: int, point) -> np.ndarray:
        """World positions (m, 3) [m] of ``point`` (coordinates in joint ``joint``'s frame, a
        Pinocchio joint index ≥ 1) for each configuration row of ``q`` (m, nv)."""
        q = np.ascontiguousarray(q, dtype=float).reshape(-1, self.nv)
        p = np.ascontiguousarray(point, dtype=float).reshape(3)
        out = np.empty((q.shape[0], 3))
        self._lib.chain_point(self._ptr, q.ctypes.data, q.shape[0], joint - 1, p.ctypes.data,
                              out.ctypes.data)
        return out


class NativeOffset:
    """``d(x) = p(q0 + x_q) − (C x + y0)`` [m] compiled: the output offset of
    :class:`rhmpc.control.offset.OutputOffset` in one C call (forward kinematics of the chain).

    Parameters
    ----------
    chain : NativeChain
        The robot's compiled chain.
    joint : int
        Pinocchio index (≥ 1) of the joint carrying the end-point.
    point : array (3,)
        The end-point in that joint's frame [m].
    q0, C, y0 : arrays
        Linearisation point (nv,) [rad], output matrix (3, 2nv) and output at q0 (3,) [m].
    out : ndarray (3,), optional
        Where every call writes d (a contiguous float64 array, e.g. a controller's parameter
        slot); default its own.
    state : ndarray (2nv,), optional
        Where :meth:`evaluate` reads x (a contiguous float64 array the caller writes, e.g. the
        state slot of a controller's parameter vector, so that x is not copied twice); default
        its own.
    """

    def __init__(self, chain: NativeChain, joint: int, point, q0, C, y0,
                 out: np.ndarray | None = None, state: np.ndarray | None = None) -> None:
        nv = chain.nv
        self._chain = chain  # the C structure the call points to lives in it
        self._keep = [np.ascontiguousarray(a, dtype=float).reshape(-1).copy()
                      for a in (point, q0, C, y0)]
        if [a.size for a in self._keep] != [3, nv, 6 * nv, 3]:
            raise ValueError("point (3,), q0 (nv,), C (3, 2nv) and y0 (3,) expected")
        self._x = np.zeros(2 * nv) if state is None else state
        self.out = np.zeros(3) if out is None else out  #: the last offset (overwritten)
        for name, a, n in (("out", self.out, 3), ("state", self._x, 2 * nv)):
            if a.shape != (n,) or a.dtype != np.float64 or not a.flags.c_contiguous:
                raise ValueError(f"{name} must be a contiguous float64 array of {n}")
        point, q0, C, y0 = (a.ctypes.data for a in self._keep)
        self._call = functools.partial(chain._lib.chain_offset, chain._ptr, self._x.ctypes.data,
                                       q0, C, y0, joint - 1, point, self.out.ctypes.data)

    def evaluate(self) -> np.ndarray:
        """The offset at the x already in the ``state`` array (returns :attr:`out`)."""
        self._call()
        return self.out


def _bodies(model) -> list[tuple[int, float, float, tuple[float, float, float]]] | None:
    """(degree of freedom, scale, offset, axis) of each body's joint; None if one is not a
    revolute joint (or a mimic of one)."""
    import pinocchio as pin

    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    out = []
    for i, joint in enumerate(model.joints[1:], start=1):
        name = joint.shortname()
        if name in _AXES or name == "JointModelRevoluteUnaligned":
            axis = _AXES.get(name) or tuple(np.asarray(joint.extract().axis).tolist())
            out.append((joint.idx_v, 1.0, 0.0, axis))
        elif name == "JointModelMimic":
            mimic = joint.extract()
            S = np.asarray(data.joints[i].S).reshape(6, -1)[:, 0]
            if np.abs(S[:3]).max() > 0 or mimic.scaling == 0:  # a translation: not revolute
                return None
            out.append((joint.idx_v, float(mimic.scaling), float(mimic.offset),
                        tuple((S[3:] / mimic.scaling).tolist())))
        else:
            return None
    return out


def load_chain(model, damping=0.0, coulomb=0.0, stiction_velocity: float = 5e-3,
               motor_map=None) -> NativeChain | None:
    """The compiled dynamics of a Pinocchio ``model``, or None (reason in ``unavailable_reason``).

    Parameters
    ----------
    model : pinocchio.Model
        A chain or tree of revolute joints (RX, RY, RZ, revolute-unaligned), at most 8 bodies;
        bodies on mimic joints of revolute joints follow their degree of freedom (then the
        forward dynamics is M⁻¹(τ − h) instead of ABA).
    damping, coulomb : float or array
        Viscous [N·m·s/rad] and Coulomb [N·m] friction of each motor, for
        :meth:`NativeChain.midpoint`.
    stiction_velocity : float
        v_s of the smoothed Coulomb friction [rad/s].
    motor_map : array or None
        S, the motors' output rates ω = S q̇ the friction acts on (None: identity).
    """
    global unavailable_reason
    bodies = _bodies(model)
    names = [j.shortname() for j in model.joints[1:]]
    if bodies is None or not 0 < model.nv <= len(bodies) <= MAX_JOINTS or model.nq != model.nv:
        unavailable_reason = f"joints {', '.join(names)}: only revolute chains are compiled"
        return None
    library = _compile()
    if library is None:
        return None
    nv = model.nv
    chain = _Chain()
    chain.n, chain.nb = nv, len(bodies)
    damping = np.broadcast_to(np.asarray(damping, dtype=float), (nv,))
    coulomb = np.broadcast_to(np.asarray(coulomb, dtype=float), (nv,))
    S = np.eye(nv) if motor_map is None else np.asarray(motor_map, dtype=float)
    chain.motor[: nv * nv] = S.reshape(-1).tolist()
    chain.mapped = int(not np.array_equal(S, np.eye(nv)))
    for k, (coord, scale, offset, axis) in enumerate(bodies):
        i = k + 1
        chain.parent[k] = int(model.parents[i]) - 1
        chain.coord[k], chain.scale[k], chain.offset[k] = coord, scale, offset
        chain.projected |= int(coord != k or scale != 1.0 or offset != 0.0)
        placement = model.jointPlacements[i]
        chain.Rp[k][:] = np.asarray(placement.rotation).reshape(-1).tolist()
        chain.pp[k][:] = np.asarray(placement.translation).tolist()
        chain.axis[k][:] = list(axis)
        M = np.asarray(model.inertias[i].matrix())  # Pinocchio's (linear; angular) order
        M = np.block([[M[3:, 3:], M[3:, :3]], [M[:3, 3:], M[:3, :3]]])
        chain.inertia[k][:] = M.reshape(-1).tolist()
    for j in range(nv):
        chain.armature[j] = float(model.armature[j])
        chain.damping[j], chain.coulomb[j] = float(damping[j]), float(coulomb[j])
    chain.inv_stiction = 1.0 / stiction_velocity
    chain.gravity[:] = np.asarray(model.gravity.linear).tolist()
    unavailable_reason = None
    return NativeChain(library, chain, nv)


class _Hardware(ctypes.Structure):
    """``hw_t`` of sim/plant/chain.c."""

    _fields_ = [
        ("arm", ctypes.c_void_p), ("cables", _i), ("steps", _i),
        ("S", _d * (MAX_JOINTS * MAX_JOINTS)), ("gain", _d * MAX_JOINTS),
        ("coulomb", _d * MAX_JOINTS), ("damping", _d * MAX_JOINTS), ("ratio", _d),
        ("v_stribeck", _d), ("inv_smooth", _d), ("rotor", _d * MAX_JOINTS),
        ("R", _d * (MAX_JOINTS * MAX_JOINTS)), ("k", _d * MAX_JOINTS), ("c", _d * MAX_JOINTS),
        ("q0", _d * MAX_JOINTS), ("tau_e", _d), ("h", _d),
    ]


class HardwareStep:
    """The hardware-like plant's tick compiled (``hw_integrate``): the equations of
    :class:`sim.plant.hardware.HardwareTick`, whose Python steps are the reference, with its
    parameters: the arm's chain, motor map S, torque per ampere η K_t, friction (Coulomb,
    viscous, stiction, Stribeck, smoothing), rotor inertias, cables (None: rigid), home
    posture, current lag τ_e and step h."""

    def __init__(self, chain: NativeChain, *, S, gain, coulomb, damping, ratio, v_stribeck,
                 v_smooth, rotor, cables, q0, tau_e, h, steps) -> None:
        n = chain.nv
        w = self._w = _Hardware()
        self._chain = chain  # kept alive: w.arm points into it
        w.arm, w.steps, w.cables = chain._ptr, steps, int(cables is not None)
        w.S[: n * n] = np.asarray(S, dtype=float).reshape(-1).tolist()
        R = np.asarray(S).T @ np.diag(rotor) @ np.asarray(S)
        w.R[: n * n] = R.reshape(-1).tolist()
        for name, value in (("gain", gain), ("coulomb", coulomb), ("damping", damping),
                            ("rotor", rotor), ("q0", q0)):
            getattr(w, name)[:n] = np.broadcast_to(np.asarray(value, dtype=float), (n,)).tolist()
        if cables is not None:
            w.k[:n], w.c[:n] = np.asarray(cables[0]).tolist(), np.asarray(cables[1]).tolist()
        w.ratio, w.v_stribeck, w.inv_smooth = ratio, v_stribeck, 1.0 / v_smooth
        w.tau_e, w.h = tau_e, h
        self._x, self._i, self._cmd = np.zeros(4 * n), np.zeros(n), np.zeros(n)
        self._args = (ctypes.addressof(w), self._x.ctypes.data, self._i.ctypes.data,
                      self._cmd.ctypes.data)
        self._fn = chain._lib.hw_integrate
        self.n = n

    def integrate(self, state: list, current: np.ndarray, command: np.ndarray
                  ) -> tuple[list, np.ndarray]:
        """One tick from ``state`` = [q, q̇, θ_r, θ̇_r] with winding currents ``current`` and
        the held current command; returns the new state and currents."""
        n = self.n
        self._x[:] = np.concatenate(state)
        self._i[:], self._cmd[:] = current, command
        self._fn(*self._args)
        x = self._x.copy()
        return [x[k * n:(k + 1) * n] for k in range(4)], self._i.copy()


class _Tick(ctypes.Structure):
    """``tick_t`` of sim/plant/chain.c."""

    _fields_ = [
        ("plant", ctypes.c_void_p), ("model", ctypes.c_void_p), ("h", _d), ("substeps", _i),
        ("quantise", _i), ("resolution", _d * MAX_JOINTS), ("inv_resolution", _d * MAX_JOINTS),
        ("tau_max", _d * MAX_JOINTS), ("correct", (_d * (3 * MAX_JOINTS + 1)) * (2 * MAX_JOINTS)),
        ("predict", (_d * (3 * MAX_JOINTS)) * (2 * MAX_JOINTS)), ("q", _d * MAX_JOINTS),
        ("v", _d * MAX_JOINTS), ("prior", _d * (3 * MAX_JOINTS + 1)),
        ("post", _d * (3 * MAX_JOINTS)), ("u", _d * MAX_JOINTS), ("tau", _d * MAX_JOINTS),
        ("saturated", _i),
    ]


class _Records(ctypes.Structure):
    """``records_t`` of sim/plant/chain.c: a chunk's records for :meth:`NativeTick.run_ticks`."""

    _fields_ = [*((k, ctypes.c_void_p) for k in ("control", "state", "last", "parts", "tau_mpc",
                                                  "tau", "q", "ref0", "x_saved")),
                ("every", _i), ("phase", _i), ("points", ctypes.c_void_p),
                ("plan", ctypes.c_void_p), ("ref_saved", ctypes.c_void_p), ("ref_len", _i)]


class NativeTick:
    """:class:`sim.plant.tick.ArmTick` compiled: the robot's side of a tick in three C calls.

    ``sense()`` quantises the plant's joint angles (encoders) and corrects the observer, and
    returns x̂ = [q − q0; q̇] (a view); ``actuate(u)`` computes the commanded torque
    τ = u + ĝ + Ĉq̇ + f̂ at the estimate; ``advance()`` clips it, integrates the plant one tick
    (explicit midpoint) and predicts the observer with the MPC torque that acted. The same
    operations in the same order as :class:`~sim.plant.tick.ArmTick` with the
    :class:`~sim.plant.ArmPlant`, :class:`~sim.plant.NonlinearityCancellation` and
    :class:`~sim.plant.observer.JointObserver` whose settings and state it copies, up to rounding.
    """

    dynamics, dynamics_note = "native", None

    def __init__(self, plant, cancellation, observer, encoder_resolution) -> None:
        nv = plant.robot.nv
        s = plant.settings
        self._plant = load_chain(plant.model, plant.damping, plant.coulomb_friction,
                                 s.stiction_velocity, plant.robot.motor_map)
        self._model = load_chain(cancellation.model, cancellation.damping,
                                 cancellation.coulomb_friction, cancellation.stiction_velocity,
                                 cancellation.motor_map)
        if self._plant is None or self._model is None or s.integrator != "midpoint":
            raise ValueError(f"no native tick: {unavailable_reason or s.integrator}")
        lib = self._plant._lib
        t = self._tick = _Tick()
        t.plant, t.model = self._plant._ptr, self._model._ptr
        t.h, t.substeps = plant.substep, s.substeps
        t.quantise = encoder_resolution is not None
        if t.quantise:
            res = np.broadcast_to(np.asarray(encoder_resolution, dtype=float), (nv,))
            t.resolution[:nv] = res.tolist()
            t.inv_resolution[:nv] = (1.0 / res).tolist()
        t.tau_max[:nv] = plant.robot.torque_limit.tolist()
        for k, row in enumerate(observer.correct_matrix):
            t.correct[k][: row.size] = row.tolist()
        for k, row in enumerate(observer.predict_matrix):
            t.predict[k][: row.size] = row.tolist()
        t.q[:nv], t.v[:nv] = plant.q.tolist(), plant.v.tolist()
        t.prior[: 2 * nv] = observer.x_prior.tolist()
        address = ctypes.addressof(t)

        def view(name: str, count: int, offset: int = 0) -> np.ndarray:
            field = getattr(_Tick, name)
            return np.ctypeslib.as_array((_d * count).from_address(
                address + field.offset + 8 * offset))

        self.x = view("post", 2 * nv)  #: x̂ after ``sense`` (the observer's estimate)
        self.u = view("u", nv)  #: τ_mpc of the last ``actuate``
        self.tau = view("tau", nv)  #: commanded torque after ``actuate`` [N·m]
        self.q = view("q", nv)  #: the plant's joint angles [rad] (changed in place)
        self.v = view("v", nv)
        self._ptr = ctypes.c_void_p(address)
        # the compiled functions bound to this tick (no Python frame of their own)
        self._sense = functools.partial(lib.tick_sense, self._ptr)
        self._actuate = functools.partial(lib.tick_actuate, self._ptr)
        self.advance = functools.partial(lib.tick_advance, self._ptr)
        self.nv = nv
        self._records = _Records()
        self._run = functools.partial(lib.tick_run_gil, self._ptr,
                                      ctypes.addressof(self._records))
        self._keep: tuple = ()
        self._rows = 0  # rows of the bound records

    def bind(self, control, log: dict, every: int, phase: int, plan=None) -> None:
        """Point :meth:`run_ticks` at a compiled controller and at a chunk's records.

        Parameters
        ----------
        control
            The controller's tick in C: ``function``, ``state``, ``output`` (nv,)
            (:class:`rhmpc.control.export.CompiledTick`).
        log : dict
            The chunk's records (:meth:`sim.loop.results.Recorder.start_chunk`): ``parts_ns``
            (m, 3) int64, ``tau_mpc``, ``tau``, ``q`` (m, nv), ``ref0`` (m, 3), ``x_saved``,
            all C-ordered.
        every, phase : int
            x̂ of the rows k ≡ phase (mod every) is kept in row k // every of ``x_saved``
            (every = 0: none).
        plan : optional
            A chunk's refresh slices (:class:`rhmpc.control.compiled_reference.CompiledSlices`):
            each tick runs those due on it and reads its points there; the kept x̂'s points go
            to ``log["ref_saved"]``. None: the points are :meth:`run_ticks`' ``refs``.
        """
        names = ("parts_ns", "tau_mpc", "tau", "q", "ref0", "x_saved") + (
            () if plan is None else ("ref_saved",))
        arrays = [np.asarray(control.output)] + [log[k] for k in names]
        m, n = log["parts_ns"].shape[0], self.nv
        kept = m // every + 1 if every else 0
        shapes = [((n,), np.float64), ((m, 3), np.int64), ((m, n), np.float64),
                  ((m, n), np.float64), ((m, n), np.float64), ((m, 3), np.float64),
                  ((kept, 2 * n), np.float64), ((kept, getattr(plan, "points", 0)), np.float64)]
        for a, (shape, dtype) in zip(arrays, shapes[: len(arrays)], strict=True):
            if not (a.flags.c_contiguous and a.flags.writeable) or a.dtype != dtype \
                    or a.shape[0] < shape[0] or a.shape[1:] != shape[1:]:
                raise ValueError(f"the compiled ticks write C-contiguous, writeable {dtype} "
                                 f"arrays {shape}, got {a.dtype} {a.shape}")
        self._rows = m
        r = self._records
        r.control, r.state = control.function, control.state
        r.last, r.parts, r.tau_mpc, r.tau, r.q, r.ref0, r.x_saved = (
            a.ctypes.data for a in arrays[:7])
        r.every, r.phase = every, phase
        r.points, r.plan, r.ref_saved, r.ref_len = (None, None, None, 0) if plan is None else (
            plan.function, plan.state, arrays[7].ctypes.data, plan.points)
        self._keep = (control, arrays, plan)  # alive while the C side points at them

    def run_ticks(self, k0: int, count: int, refs: int, ref_step: int,
                  u_first: int | None = None) -> None:
        """Rows k0 … k0 + count − 1 of the bound records in one C call (:meth:`bind`): per tick
        ``sense``, the controller on x̂ and the tick's N reference points, ``actuate`` and
        ``advance``, timed as the Python loop times them. ``refs``: the address of the first
        tick's C-ordered (N, 3) float64 points, the next ``ref_step`` doubles further (3 for
        overlapping windows; unused with a plan). ``u_first``: u_{−1}'s address, or None."""
        if not 0 <= k0 <= k0 + count <= self._rows:
            raise ValueError(f"rows {k0}…{k0 + count - 1} are outside the {self._rows} bound")
        self._run(k0, count, refs, ref_step, u_first)

    def sense(self) -> np.ndarray:
        """x̂ = [q − q0; q̇] from the encoders (a view of the C state: read, don't keep)."""
        self._sense()
        return self.x

    def actuate(self, u: np.ndarray) -> np.ndarray:
        """The commanded torque τ = u + ĝ + Ĉq̇ + f̂ at the estimate [N·m] (a view)."""
        self.u[:] = u
        self._actuate()
        return self.tau

    @property
    def saturated(self) -> bool:
        """Whether the last ``advance`` clipped the torque."""
        return bool(self._tick.saturated)
