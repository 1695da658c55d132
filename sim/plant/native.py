"""The plant's dynamics compiled: the one dynamics kernel, checked against Pinocchio.

Pinocchio is the reference for the plant's dynamics; a closed-loop tick calls them four times
(two midpoint steps of two evaluations), and through Python bindings each call is mostly
argument conversion around a microsecond of arithmetic. ``sim/plant/chain.c`` computes them for
a chain or tree of revolute joints, with the parameters read from the Pinocchio model (joint
placements and axes, spatial inertias, rotor armature, gravity) and the plant's friction
``Sᵀ(D ω + F_c tanh(ω/v_s))``: recursive Newton–Euler for h(q, q̇) = C(q, q̇) q̇ + g(q), the
composite-rigid-body algorithm for M(q), and the forward dynamics as q̈ = M(q)⁻¹(τ − h) by
Cholesky, from one set of body poses, with the spatial algebra in its structured form (a
transform as a rotation and a translation, an inertia as a mass, a first moment and a rotational
inertia; Featherstone 2008, §2.8), as Pinocchio computes it. A body on a mimic joint (the
PHANToM's parallelogram) follows its degree of freedom. It holds dynamics only: the plant's
midpoint steps, the hardware-like plant's motor currents, friction and cables, and forward
kinematics for the loop's records; no controller logic. It is used where it builds
(``PlantSettings.dynamics = "auto"``), compiled at first use by :mod:`rhmpc.compiled`.

Pinocchio stays the reference: ``tests/sim/plant/test_native.py`` compares the forward
dynamics, RNEA, M and the end-point with ``pin.aba``, ``pin.rnea``, ``pin.crba`` and the frame
placement at random states, on the PHANToM and on a tree of rotated placements and an unaligned
axis. Where no compiler is found, or the model has other joints than revolute ones,
:func:`load_chain` returns None with the reason (``unavailable_reason``) and the plant runs on
Pinocchio.
"""
from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np

from rhmpc.compiled import load
from robots.model import bodies

MAX_JOINTS = 8
_SOURCE = Path(__file__).with_name("chain.c")

#: Why the compiled chain is not available (None while it is, or before the first attempt).
unavailable_reason: str | None = None
_library: ctypes.CDLL | None = None
_tried = False

_d, _i = ctypes.c_double, ctypes.c_int


class _Chain(ctypes.Structure):
    """``chain_t`` of sim/plant/chain.c."""

    _fields_ = [
        ("n", _i), ("nb", _i), ("parent", _i * MAX_JOINTS), ("coord", _i * MAX_JOINTS),
        ("scale", _d * MAX_JOINTS), ("offset", _d * MAX_JOINTS),
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
    signatures = {"chain_forward": [ptr] * 5, "chain_rnea": [ptr] * 5, "chain_mass": [ptr] * 3,
                  "chain_midpoint": [ptr, ptr, ptr, ptr, _d, _i], "hw_integrate": [ptr] * 4,
                  "chain_point": [ptr, ptr, _i, _i, ptr, ptr]}
    for name, argtypes in signatures.items():
        getattr(library, name).argtypes, getattr(library, name).restype = argtypes, None
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

    def forward_dynamics(self, q, v, tau) -> np.ndarray:
        """q̈ = M(q)⁻¹(τ − h(q, q̇)) [rad/s²] (no friction: the dynamics alone, as ``pin.aba``)."""
        self._q[:], self._v[:], self._x[:] = q, v, tau
        self._lib.chain_forward(self._ptr, *self._addr)
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


def load_chain(model, damping=0.0, coulomb=0.0, stiction_velocity: float = 5e-3,
               motor_map=None) -> NativeChain | None:
    """The compiled dynamics of a Pinocchio ``model``, or None (reason in ``unavailable_reason``).

    Parameters
    ----------
    model : pinocchio.Model
        A chain or tree of revolute joints (RX, RY, RZ, revolute-unaligned), at most 8 bodies;
        bodies on mimic joints of revolute joints follow their degree of freedom.
    damping, coulomb : float or array
        Viscous [N·m·s/rad] and Coulomb [N·m] friction of each motor, for
        :meth:`NativeChain.midpoint`.
    stiction_velocity : float
        v_s of the smoothed Coulomb friction [rad/s].
    motor_map : array or None
        S, the motors' output rates ω = S q̇ the friction acts on (None: identity).
    """
    global unavailable_reason
    try:
        tree = bodies(model)
    except ValueError as exc:
        unavailable_reason = f"{exc}: only revolute chains are compiled"
        return None
    if not 0 < model.nv <= len(tree) <= MAX_JOINTS or model.nq != model.nv:
        unavailable_reason = f"{len(tree)} bodies, {model.nv} joints: at most {MAX_JOINTS}"
        return None
    library = _compile()
    if library is None:
        return None
    nv = model.nv
    chain = _Chain()
    chain.n, chain.nb = nv, len(tree)
    damping = np.broadcast_to(np.asarray(damping, dtype=float), (nv,))
    coulomb = np.broadcast_to(np.asarray(coulomb, dtype=float), (nv,))
    S = np.eye(nv) if motor_map is None else np.asarray(motor_map, dtype=float)
    chain.motor[: nv * nv] = S.reshape(-1).tolist()
    chain.mapped = int(not np.array_equal(S, np.eye(nv)))
    for k, body in enumerate(tree):
        chain.parent[k], chain.coord[k] = body.parent, body.coord
        chain.scale[k], chain.offset[k] = body.scale, body.offset
        chain.Rp[k][:] = body.R.reshape(-1).tolist()
        chain.pp[k][:] = body.p.tolist()
        chain.axis[k][:] = body.axis.tolist()
        h = np.array([[0, -body.h[2], body.h[1]], [body.h[2], 0, -body.h[0]],
                      [-body.h[1], body.h[0], 0]])  # h×: the spatial inertia (angular; linear)
        M = np.block([[body.I_o, h], [h.T, body.mass * np.eye(3)]])
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
    :class:`sim.plant.hardware.HardwarePlant`, whose Python steps are the reference, with its
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
