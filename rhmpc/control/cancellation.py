"""The controller's cancellation of the arm's nonlinearities, from its own model.

The controller adds to its MPC torque::

    τ = τ_mpc + ĝ(q) + Ĉ(q, q̇) q̇ + Sᵀ (D̂ ω + F̂_c tanh(ω / v_s)),   ĝ + Ĉq̇ = RNEA(q̂, q̇, 0)

with ω = S q̇ the motors' output rates (S the robot's motor map). The model's masses and friction
may be scaled, or taken from another parameter set of the same robot (:class:`ModelMismatch`),
to study robustness. The controller's model is a copy, apart from the plant's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from rhmpc.robots import ROBOTS, Robot, load_robot


@dataclass(frozen=True)
class ModelMismatch:
    """How the controller's model differs from the plant (1.0 = exact knowledge).

    Attributes
    ----------
    mass_scale : float
        Factor on every link mass and rotational inertia in the controller's model [-].
    friction_scale : float
        Factor on the viscous damping and Coulomb friction the controller cancels [-].
    parameters : str or None
        A registered robot whose mass properties and friction the controller's model takes
        (``"phantom-cavusoglu"``: the published set of Çavuşoğlu et al. 2002 against the CAD
        set of ``"phantom"``); it must have the plant's joints. None: the plant's own.
    """

    mass_scale: float = 1.0
    friction_scale: float = 1.0
    parameters: str | None = None

    def __post_init__(self) -> None:
        for name in ("mass_scale", "friction_scale"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
        if self.parameters is not None and self.parameters not in ROBOTS:
            raise ValueError(f"unknown parameters {self.parameters!r}; valid robots: "
                             f"{', '.join(ROBOTS)}")


class NonlinearityCancellation:
    """The controller's estimate ĝ(q) + Ĉ(q, q̇)q̇ + f̂(q̇) from its own (possibly mismatched) model."""

    def __init__(
        self, robot: Robot, mismatch: ModelMismatch | None = None, stiction_velocity: float = 5e-3
    ) -> None:
        self.mismatch = mismatch or ModelMismatch()
        if self.mismatch.parameters is not None:
            robot = _same_joints(robot, load_robot(self.mismatch.parameters))
        self.motor_map = robot.motor_map
        # S's non-zero entries (i, j, S_ij): ω_i = Σ_j S_ij q̇_j, and (Sᵀ f)_j = Σ_i S_ij f_i
        self._entries = [(i, j, s) for (i, j), s in np.ndenumerate(self.motor_map.tolist())
                         if s != 0.0]
        self.model = robot.model.copy()
        for i, inertia in enumerate(self.model.inertias):
            self.model.inertias[i] = pin.Inertia(
                inertia.mass * self.mismatch.mass_scale,
                inertia.lever,
                inertia.inertia * self.mismatch.mass_scale,
            )
        self.data = self.model.createData()
        self.stiction_velocity = float(stiction_velocity)
        self._inv_stiction = 1.0 / stiction_velocity
        scale, nv = self.mismatch.friction_scale, robot.nv
        #: D̂ and F̂_c per joint, the friction the controller cancels [N·m·s/rad], [N·m]
        self.damping = np.broadcast_to(robot.damping * scale, (nv,)).copy()
        self.coulomb_friction = np.broadcast_to(robot.coulomb_friction * scale, (nv,)).copy()
        self._friction = list(zip(self.damping.tolist(), self.coulomb_friction.tolist(),
                                  strict=True))
        self._zero = np.zeros(robot.nv)

    def torque(self, q: np.ndarray, v: np.ndarray, tau_mpc: np.ndarray | None = None) -> np.ndarray:
        """Cancellation torque [N·m] at the estimated state (q, q̇), plus ``tau_mpc`` if given.

        ``torque(q, v, u)`` is the commanded τ = u + ĝ + Ĉq̇ + f̂ in one pass (the loop's form).
        The friction's few products run on Python floats: for three joints a dozen NumPy calls
        would cost several times the arithmetic.
        """
        u = self._zero if tau_mpc is None else tau_mpc
        if u.shape != self._zero.shape or v.shape != self._zero.shape:
            raise ValueError(f"v and tau_mpc must have shape {self._zero.shape}")
        bias = pin.rnea(self.model, self.data, q, v, self._zero).tolist()
        rates, inv_vs, tanh = v.tolist(), self._inv_stiction, math.tanh
        w = [0.0] * len(rates)
        for i, j, s in self._entries:  # ω = S q̇
            w[i] += s * rates[j]
        f = [d * x + c * tanh(x * inv_vs) for (d, c), x in zip(self._friction, w)]
        tau = [t + b for t, b in zip(u.tolist(), bias)]
        for i, j, s in self._entries:  # + Sᵀ f
            tau[j] += s * f[i]
        return np.array(tau)


def _same_joints(plant: Robot, model: Robot) -> Robot:
    """``model`` if it has the plant's joints and motor map; else ValueError."""
    if model.nv != plant.nv or not np.array_equal(model.motor_map, plant.motor_map):
        raise ValueError(f"parameters {model.name!r} do not have the joints of {plant.name!r}")
    return model
