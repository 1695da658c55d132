"""The plant: the full nonlinear arm, Pinocchio's forward dynamics integrated over a tick.

With the joint torque ``τ`` held constant over a control tick::

    M(q) q̈ + C(q, q̇) q̇ + g(q) = τ − Sᵀ (D ω + F_c tanh(ω / v_s)),   ω = S q̇

``M`` includes the reflected rotor inertia (armature); ``D`` is viscous damping and ``F_c``
Coulomb friction of each motor, acting on its output rate ω (``S`` the robot's motor map, the
identity where each joint has its own motor), smoothed by ``tanh`` over the stiction velocity
``v_s`` so that the ODE stays integrable. ABA solves for q̈; a model with mimic bodies (a
parallelogram as a tree) is solved as M⁻¹(τ − h) (:func:`robots.model.forward_dynamics`). The
controller's cancellation of these terms is :mod:`sim.plant.cancellation`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from robots import Robot
from robots.model import forward_dynamics

INTEGRATORS = ("midpoint", "rk4", "semi-implicit-euler")
DYNAMICS = ("auto", "native", "pinocchio")
MODELS = ("ideal", "linear", "hardware")


@dataclass(frozen=True)
class PlantSettings:
    """Which plant, and its integration.

    Attributes
    ----------
    model : str
        ``"ideal"``: the nonlinear arm, the torque applied as commanded (this module);
        ``"linear"``: the MPC's own linear model as the plant (Tuna et al.'s Table I
        simulation); ``"hardware"``: the arm behind an I/O delay, a DAC, a current amplifier,
        friction with stiction and optionally compliant cables (:mod:`sim.plant.hardware`,
        its settings in ``HardwareSettings``).
    integrator : str
        ``"midpoint"`` (explicit midpoint, 2nd order, 2 ABA calls per step), ``"rk4"``
        (classical Runge–Kutta, 4 calls) or ``"semi-implicit-euler"`` (symplectic Euler, 1 call).
    substeps : int
        Integration steps per control tick; the step is ``Ts / substeps`` [s]. The default,
        midpoint with 2 steps of 0.25 ms, has a local error per tick below 0.5 µm at the
        end-effector against RK4 with 500 steps (tests/sim/test_plant.py), at half the cost of RK4
        with 2 steps. One step of 0.5 ms: 1.4 µm per tick (measured 1.36 against 0.36 µm, worst
        of 100 random states), which moved a 20-s run's RMS error by 0.06 % and would save
        half of the native midpoint step's ≈ 2 µs a tick: not worth a 4× larger local error.
    stiction_velocity : float
        Velocity scale ``v_s`` of the smoothed Coulomb friction [rad/s].
    dynamics : str
        Who computes the midpoint steps: ``"pinocchio"`` (``pin.aba``, the reference),
        ``"native"`` (the same equations compiled from C, :mod:`sim.plant.native`, within
        1e-15 relative of ``pin.aba``) or ``"auto"`` (native where a C compiler is found and the
        robot is a revolute chain, else Pinocchio; ``dynamics_note`` says why). Other
        integrators always use Pinocchio.
    """

    integrator: str = "midpoint"
    substeps: int = 2
    stiction_velocity: float = 5e-3
    dynamics: str = "auto"
    model: str = "ideal"

    def __post_init__(self) -> None:
        if self.model not in MODELS:
            raise ValueError(f"unknown plant model {self.model!r}; valid: {', '.join(MODELS)}")
        if self.integrator not in INTEGRATORS:
            raise ValueError(
                f"unknown integrator {self.integrator!r}; valid: {', '.join(INTEGRATORS)}"
            )
        if self.substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {self.substeps}")
        if not self.stiction_velocity > 0:
            raise ValueError(f"stiction_velocity must be > 0 [rad/s], got {self.stiction_velocity}")
        if self.dynamics not in DYNAMICS:
            raise ValueError(f"unknown dynamics {self.dynamics!r}; valid: {', '.join(DYNAMICS)}")


class ArmPlant:
    """Forward dynamics of ``robot`` integrated over control ticks of ``Ts`` seconds.

    Torques are clipped to the actuator limits before they act. ``q`` and ``v`` [rad, rad/s]
    are replaced by every ``step``, never changed in place (a reference to them stays valid).
    """

    def __init__(self, robot: Robot, Ts: float, settings: PlantSettings | None = None) -> None:
        self.robot = robot
        self.settings = settings or PlantSettings()
        self.Ts = float(Ts)
        self.model = robot.model
        self.data = robot.create_data()
        self._damping = robot.damping
        self._coulomb = robot.coulomb_friction
        self._damping_list = np.broadcast_to(robot.damping, (robot.nv,)).tolist()
        self._coulomb_list = np.broadcast_to(robot.coulomb_friction, (robot.nv,)).tolist()
        self._inv_stiction = 1.0 / self.settings.stiction_velocity
        self._tau_max_list = robot.torque_limit.tolist()
        self._tau_min_list = (-robot.torque_limit).tolist()
        self._substeps = self.settings.substeps
        self._h = self.Ts / self.settings.substeps
        self._S = robot.motor_map
        self._plain = not robot.has_mimic and np.array_equal(self._S, np.eye(robot.nv))
        self._advance = {  # all substeps of one tick, torque given as a list of floats
            "midpoint": self._midpoint_steps if self._plain
            else self._substeps_of(self._midpoint),
            "rk4": self._substeps_of(self._rk4),
            "semi-implicit-euler": self._substeps_of(self._symplectic_euler),
        }[self.settings.integrator]
        self.q = robot.q0.copy()
        self.v = np.zeros(robot.nv)
        self.saturated = False  # whether the last step clipped the torque
        self._shape = (robot.nv,)
        #: "native" or "pinocchio": who integrates; ``dynamics_note`` says why not native
        self.dynamics, self.dynamics_note = "pinocchio", None
        if self.settings.dynamics != "pinocchio":
            self._use_native()

    def _use_native(self) -> None:
        from sim.plant import native

        chain = None
        if self.settings.integrator == "midpoint":
            chain = native.load_chain(self.model, self._damping, self._coulomb,
                                      self.settings.stiction_velocity, self._S)
            note = native.unavailable_reason
        else:
            note = f"the {self.settings.integrator} integrator runs on Pinocchio"
        if chain is None:
            if self.settings.dynamics == "native":
                raise ValueError(f"native plant dynamics unavailable: {note}")
            self.dynamics_note = note
            return
        self._chain, self._advance, self.dynamics = chain, self._native_steps, "native"

    def _native_steps(self, tau: list[float]) -> None:
        """:meth:`_midpoint_steps` compiled (:mod:`sim.plant.native`), one call per tick."""
        self.q, self.v = self._chain.midpoint(self.q, self.v, tau, self._h, self._substeps)

    @property
    def damping(self) -> np.ndarray:
        """Viscous friction D per joint [N·m·s/rad]."""
        return np.broadcast_to(self._damping, self._shape)

    @property
    def coulomb_friction(self) -> np.ndarray:
        """Coulomb friction F_c per joint [N·m]."""
        return np.broadcast_to(self._coulomb, self._shape)

    @property
    def substep(self) -> float:
        """Integration step h = Ts / substeps [s]."""
        return self._h

    def reset(self, q: np.ndarray | None = None, v: np.ndarray | None = None) -> None:
        """Place the arm at ``q`` (default home) with velocity ``v`` (default rest)."""
        self.q = self.robot.check_posture(self.robot.q0 if q is None else q).copy()
        self.v = np.zeros(self.robot.nv) if v is None else np.asarray(v, dtype=float).copy()

    def encoders(self) -> np.ndarray:
        """The encoders' joint angles q̃ = Δ·round(q/Δ) [rad] (q without an encoder model)."""
        res = self.robot.encoder_resolution
        return self.q if res is None else res * np.rint(self.q / res)

    def friction(self, v: np.ndarray) -> np.ndarray:
        """Joint friction torque Sᵀ (D ω + F_c tanh(ω / v_s)), ω = S q̇, opposing the motion
        [N·m]."""
        w = self._S @ v
        f = self._damping * w + self._coulomb * np.tanh(w / self.settings.stiction_velocity)
        return self._S.T @ f

    def acceleration(self, q: np.ndarray, v: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """q̈ = M⁻¹ (τ − friction(q̇) − h(q, q̇)) [rad/s²] (ABA where the model allows)."""
        return forward_dynamics(self.model, self.data, q, v, np.subtract(tau, self.friction(v)))

    def step(self, tau: np.ndarray) -> np.ndarray:
        """Advance one control tick with ``tau`` [N·m] held constant; returns the applied torque.

        The torque is clipped to ±``torque_limit``; ``saturated`` tells whether it was.
        """
        # Clipped on floats (cheaper than two ufunc calls for a 3-vector); the substeps take
        # the list.
        commanded_array = np.asarray(tau, dtype=float)
        if commanded_array.shape != self._shape:
            raise ValueError(f"tau must have shape {self._shape}, got {commanded_array.shape}")
        commanded = commanded_array.tolist()
        # zip without strict=: the lengths are checked above (strict costs ≈ 1 µs per call)
        tau = [min(max(t, lo), hi)
               for t, lo, hi in zip(commanded, self._tau_min_list, self._tau_max_list)]
        self.saturated = tau != commanded
        self._advance(tau)
        return np.array(tau) if self.saturated else commanded_array

    def _substeps_of(self, step):
        def advance(tau: list[float]) -> None:
            for _ in range(self._substeps):
                step(tau)
        return advance

    def _symplectic_euler(self, tau: np.ndarray) -> None:
        h = self._h
        self.v = self.v + h * self.acceleration(self.q, self.v, tau)
        self.q = self.q + h * self.v

    def _midpoint(self, tau: list[float]) -> None:
        """One explicit-midpoint step of h (the equations of :meth:`_midpoint_steps`)."""
        h, acc = self._h, self.acceleration
        v_mid = self.v + 0.5 * h * acc(self.q, self.v, tau)
        q_mid = self.q + 0.5 * h * self.v
        self.q, self.v = self.q + h * v_mid, self.v + h * acc(q_mid, v_mid, tau)

    def _midpoint_steps(self, tau: list[float]) -> None:
        """Explicit midpoint, ``substeps`` times: with a = ABA(q, q̇, τ − D q̇ − F_c tanh(q̇/v_s)),

            q̇½ = q̇ + (h/2) a(q, q̇),   q½ = q + (h/2) q̇,
            q⁺ = q + h q̇½,            q̇⁺ = q̇ + h a(q½, q̇½).

        The hot path of the simulator (4 ABA calls per tick): the 3-vector arithmetic runs on
        Python floats and arrays are made only for the ABA calls — 14 % faster than numpy
        ufuncs on 3-vectors here (measured 26.7 vs 31.0 µs per tick, best of 20), same results
        to the last bit.
        """
        h, model, data, aba, tanh = self._h, self.model, self.data, pin.aba, math.tanh
        hh, inv_vs, array = 0.5 * h, self._inv_stiction, np.array
        joints = list(zip(tau, self._damping_list, self._coulomb_list, strict=True))
        q, v = self.q.tolist(), self.v.tolist()
        for _ in range(self._substeps):
            f = array([t - d * x - c * tanh(x * inv_vs) for (t, d, c), x in zip(joints, v)])
            a = aba(model, data, array(q), array(v), f).tolist()
            v_mid = [x + hh * y for x, y in zip(v, a)]
            q_mid = [x + hh * y for x, y in zip(q, v)]
            f = array([t - d * x - c * tanh(x * inv_vs) for (t, d, c), x in zip(joints, v_mid)])
            a = aba(model, data, array(q_mid), array(v_mid), f).tolist()
            q = [x + h * y for x, y in zip(q, v_mid)]
            v = [x + h * y for x, y in zip(v, a)]
        self.q, self.v = array(q), array(v)

    def _rk4(self, tau: np.ndarray) -> None:
        h, q, v, acc = self._h, self.q, self.v, self.acceleration
        a1 = acc(q, v, tau)
        v2 = v + 0.5 * h * a1
        a2 = acc(q + 0.5 * h * v, v2, tau)
        v3 = v + 0.5 * h * a2
        a3 = acc(q + 0.5 * h * v2, v3, tau)
        v4 = v + h * a3
        a4 = acc(q + h * v3, v4, tau)
        self.q = q + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
        self.v = v + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
