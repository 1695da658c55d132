"""The plant's dynamics kernel, ``sim/plant/chain.c``: the one place the plant's equations live.

It holds a tree of revolute joints' rigid-body dynamics, with the parameters of a Pinocchio
model (joint placements and axes, spatial inertias, rotor armature, gravity): recursive
Newton–Euler for h(q, q̇) = C(q, q̇) q̇ + g(q), the composite-rigid-body algorithm for M(q), and
the forward dynamics q̈ = M(q)⁻¹(τ − h) by Cholesky (Featherstone, *Rigid Body Dynamics
Algorithms*, 2008, chapters 5–6); a body on a mimic joint (the PHANToM's parallelogram) follows
its degree of freedom. And it holds the drives between the motor commands and the arm, integrated
over a tick (:class:`Drive`; the equations are :mod:`rhmpc.sim.plant.hardware`'s). Both plants of
:mod:`rhmpc.sim.plant` compose it. It is compiled at first use by :mod:`rhmpc.compiled`; where it
cannot be (no C compiler, a joint that is not revolute), building a plant is a one-line
``ValueError``. Pinocchio is the reference: ``tests/sim/plant/test_kernel.py`` compares it with
``pin.aba``, ``pin.rnea``, ``pin.crba`` and with a plain midpoint integration written in the test.
"""
from __future__ import annotations

import ctypes
import functools
from pathlib import Path

import numpy as np

from rhmpc.compiled import load
from rhmpc.robots.model import bodies

MAX_JOINTS = 8
_SOURCE = Path(__file__).with_name("chain.c")
_d, _i, _p = ctypes.c_double, ctypes.c_int, ctypes.c_void_p
_VECTOR, _MATRIX = _d * MAX_JOINTS, _d * (MAX_JOINTS * MAX_JOINTS)


class _Chain(ctypes.Structure):
    """``chain_t`` of sim/plant/chain.c."""

    _fields_ = [
        ("n", _i), ("nb", _i), ("parent", _i * MAX_JOINTS), ("coord", _i * MAX_JOINTS),
        ("scale", _VECTOR), ("offset", _VECTOR), ("Rp", (_d * 9) * MAX_JOINTS),
        ("pp", (_d * 3) * MAX_JOINTS), ("axis", (_d * 3) * MAX_JOINTS),
        ("inertia", (_d * 36) * MAX_JOINTS), ("armature", _VECTOR), ("gravity", _d * 3),
    ]


class _Plant(ctypes.Structure):
    """``plant_t`` of sim/plant/chain.c."""

    _fields_ = [
        ("arm", _p), ("cables", _i), ("steps", _i), ("S", _MATRIX), ("gain", _VECTOR),
        ("coulomb", _VECTOR), ("damping", _VECTOR), ("ratio", _d), ("v_stribeck", _d),
        ("inv_smooth", _d), ("rotor", _VECTOR), ("R", _MATRIX), ("k", _VECTOR), ("c", _VECTOR),
        ("q0", _VECTOR), ("tau_e", _d), ("h", _d), ("tau_max", _VECTOR), ("map", _MATRIX),
        ("c_max", _d), ("c_step", _d),
    ]


class _Loop(ctypes.Structure):
    """``loop_t`` of sim/plant/chain.c: the controller's step and the public fields the loop
    records (:meth:`Drive.run`)."""

    _fields_ = [
        ("step", _p), ("horizon", _p), ("ctl", _p), ("res", _p), ("u", _p), ("tau_command", _p),
        ("step_ns", _p),
    ]


@functools.cache
def _library() -> ctypes.CDLL:
    """The compiled kernel (built once per source version); ValueError where it cannot be."""
    library, reason = load(_SOURCE, "chain")
    if library is None:
        raise ValueError(f"the plant's dynamics kernel (sim/plant/chain.c) cannot be built: "
                         f"{reason}")
    for name, argtypes in {"chain_forward": [_p] * 5, "chain_rnea": [_p] * 5,
                           "chain_mass": [_p] * 3, "plant_tick": [_p] * 4}.items():
        getattr(library, name).argtypes, getattr(library, name).restype = argtypes, None
    library.plant_tick.restype = _i
    library.plant_run.argtypes = [_p] * 4 + [ctypes.c_longlong, _i] + [_p] * 6
    library.plant_run.restype = _i
    return library


def _fill(field, values) -> None:
    """Copy ``values`` (flattened) into the start of a ctypes array ``field``."""
    flat = np.asarray(values, dtype=float).reshape(-1).tolist()
    field[: len(flat)] = flat


class Chain:
    """The rigid-body dynamics of a Pinocchio ``model`` (a tree of at most 8 revolute bodies;
    bodies on mimic joints follow their degree of freedom).

    Raises
    ------
    ValueError
        A joint that is not revolute, too many bodies, or no kernel (no C compiler).
    """

    def __init__(self, model) -> None:
        tree = bodies(model)
        if not 0 < model.nv <= len(tree) <= MAX_JOINTS or model.nq != model.nv:
            raise ValueError(f"the plant's kernel takes at most {MAX_JOINTS} revolute bodies, "
                             f"got {len(tree)} bodies for {model.nv} joints")
        self._lib, self.nv = _library(), model.nv
        c = self._c = _Chain(n=model.nv, nb=len(tree))
        for k, body in enumerate(tree):
            c.parent[k], c.coord[k] = body.parent, body.coord
            c.scale[k], c.offset[k] = body.scale, body.offset
            _fill(c.Rp[k], body.R), _fill(c.pp[k], body.p), _fill(c.axis[k], body.axis)
            hx = np.array([[0, -body.h[2], body.h[1]], [body.h[2], 0, -body.h[0]],
                           [-body.h[1], body.h[0], 0]])  # the spatial inertia (angular; linear)
            _fill(c.inertia[k], np.block([[body.I_o, hx], [hx.T, body.mass * np.eye(3)]]))
        _fill(c.armature, model.armature)
        _fill(c.gravity, model.gravity.linear)
        self.address = ctypes.addressof(c)

    def _call(self, name: str, *arrays) -> np.ndarray:
        args = [np.ascontiguousarray(a, dtype=float) for a in arrays]
        out = np.empty(self.nv)
        getattr(self._lib, name)(self.address, *(a.ctypes.data for a in args), out.ctypes.data)
        return out

    def forward_dynamics(self, q, v, tau) -> np.ndarray:
        """q̈ = M(q)⁻¹(τ − h(q, q̇)) [rad/s²] (as ``pin.aba``)."""
        return self._call("chain_forward", q, v, tau)

    def rnea(self, q, v, a) -> np.ndarray:
        """τ = M(q) q̈ + h(q, q̇) [N·m] (as ``pin.rnea``)."""
        return self._call("chain_rnea", q, v, a)

    def mass(self, q) -> np.ndarray:
        """M(q) with the armature [kg·m²] (as ``pin.crba``, both triangles)."""
        out = np.empty((self.nv, self.nv))
        q = np.ascontiguousarray(q, dtype=float)
        self._lib.chain_mass(self.address, q.ctypes.data, out.ctypes.data)
        return out


class Drive:
    """The arm behind its drives, one tick at a time (``plant_tick``); the state lives here.

    State: x = [q, q̇, θ_r, θ̇_r] (joint angles and rates, rotor angles and rates on the output
    coordinates [rad, rad/s]) and the winding currents i [A]. :meth:`tick` takes the joint
    torques τ and holds the motors' command c = Q clip(τ, ±τ_max), rounded to the DAC's step and
    clipped to ±c_max, over ``steps`` explicit-midpoint steps of ``Ts / steps``.

    Parameters
    ----------
    chain : Chain
    Ts : float
        Control period [s].
    steps : int
        Integration steps per tick [-].
    motor_map : (n, n)
        S, the motors' output angles θ = S (q − q0) [-].
    gain : (n,)
        η K_t, output torque per unit of command [N·m/A] (1: the command is the torque).
    coulomb, damping : (n,)
        F_c [N·m] and D [N·m·s/rad] on each output.
    stiction_ratio, stribeck_velocity, smoothing_velocity : float
        F_s/F_c [-], v_S [rad/s] and v_s [rad/s] of the friction law.
    q0 : (n,)
        Home posture [rad].
    torque_limit : (n,)
        τ_max, the joint torques' limits [N·m] (inf: none).
    command_map : (n, n)
        Q, the motors' commands from the joint torques (S⁻ᵀ divided by the gain).
    full_scale, dac_step : float
        c_max, the command's limit (inf: none), and the DAC's step (0: none) [A].
    current_lag : float
        τ_e [s] (0: the current is the command).
    cables : (rotor, k, c) or None
        Rotor inertias J_r [kg·m²], cable stiffness [N·m/rad] and damping [N·m·s/rad] on each
        output (None: rigid).
    """

    def __init__(self, chain: Chain, Ts: float, steps: int, *, motor_map, gain, coulomb,
                 damping, stiction_ratio: float, stribeck_velocity: float,
                 smoothing_velocity: float, q0, torque_limit=np.inf, command_map,
                 full_scale: float = np.inf, dac_step: float = 0.0, current_lag: float = 0.0,
                 cables=None) -> None:
        n = self.n = chain.nv
        self._chain = chain  # kept alive: the plant's struct points into it
        S = np.asarray(motor_map, dtype=float)
        p = self._p = _Plant(arm=chain.address, cables=int(cables is not None), steps=steps,
                             ratio=stiction_ratio, v_stribeck=stribeck_velocity,
                             inv_smooth=1.0 / smoothing_velocity, tau_e=current_lag,
                             h=Ts / steps, c_max=full_scale, c_step=dac_step)
        _fill(p.S, S)
        _fill(p.map, command_map)
        for name, value in (("gain", gain), ("coulomb", coulomb), ("damping", damping),
                            ("q0", q0), ("tau_max", torque_limit)):
            _fill(getattr(p, name), np.broadcast_to(np.asarray(value, dtype=float), (n,)))
        if cables is not None:
            rotor, k, c = (np.asarray(a, dtype=float) for a in cables)
            _fill(p.rotor, rotor), _fill(p.k, k), _fill(p.c, c)
            _fill(p.R, S.T @ np.diag(rotor) @ S)
        self.x, self.current, self.torque = np.zeros(4 * n), np.zeros(n), np.zeros(n)
        self.x[:n] = q0
        self._loop = None  # (controller, its loop_t, the resolution it points to, the call)
        self._tick = functools.partial(chain._lib.plant_tick, ctypes.addressof(p),
                                       self.x.ctypes.data, self.current.ctypes.data,
                                       self.torque.ctypes.data)

    def tick(self, tau) -> bool:
        """One tick with the joint torques ``tau`` (n,) [N·m] held: x and the currents advance
        in place; True if a limit cut the torque or the command."""
        self.torque[:] = tau
        return bool(self._tick())

    def run(self, controller, resolution, tick: int, rows: dict) -> bool:
        """The loop's ticks ``tick`` … ``tick + m − 1`` in C (``plant_run``): the encoders'
        reading Δ·round(q/Δ) (``resolution`` Δ, or None: q), ``controller``'s step
        (:meth:`rhmpc.control.export.binding.Controller.library_loop`), this tick; ``rows`` the
        loop's records of those ticks, m rows each (``q``, ``ref0``, ``u``, ``tau``, ``cmd``,
        ``step_ns``), filled. True if a limit cut the last tick's torque or command."""
        if self._loop is None or self._loop[0] is not controller:
            res = None if resolution is None else np.ascontiguousarray(
                np.broadcast_to(np.asarray(resolution, dtype=float), (self.n,)))
            loop = _Loop(**controller.library_loop(),
                         res=None if res is None else res.ctypes.data)
            self._loop = (controller, loop, res, functools.partial(
                self._chain._lib.plant_run, ctypes.addressof(self._p), self.x.ctypes.data,
                self.current.ctypes.data, ctypes.addressof(loop)))
        return bool(self._loop[3](tick, rows["step_ns"].shape[0], *(
            rows[k].ctypes.data for k in ("q", "ref0", "u", "tau", "cmd", "step_ns"))))

    def part(self, k: int) -> np.ndarray:
        """A copy of the k-th n-vector of the state (0 q, 1 q̇, 2 θ_r, 3 θ̇_r)."""
        return self.x[k * self.n:(k + 1) * self.n].copy()

    def put(self, k: int, value) -> None:
        """Set the k-th n-vector of the state."""
        self.x[k * self.n:(k + 1) * self.n] = value


def state(k: int, doc: str) -> property:
    """A plant's ``_drive`` state part ``k`` (:meth:`Drive.part`) as a property: a copy to read,
    assignable."""
    return property(lambda plant: plant._drive.part(k),
                    lambda plant, value: plant._drive.put(k, value), doc=doc)
