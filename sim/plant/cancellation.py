"""The controller's cancellation of the arm's nonlinearities, from its own model.

The controller adds to its MPC torque::

    τ = τ_mpc + ĝ(q) + Ĉ(q, q̇) q̇ + D̂ q̇ + F̂_c tanh(q̇ / v_s),   ĝ + Ĉq̇ = RNEA(q̂, q̇, 0)

where the model's masses and friction may be scaled (:class:`ModelMismatch`) to study
robustness. The controller's model is a copy of the robot's, apart from the plant's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from robots import Robot


@dataclass(frozen=True)
class ModelMismatch:
    """How the controller's model differs from the plant (1.0 = exact knowledge).

    Attributes
    ----------
    mass_scale : float
        Factor on every link mass and rotational inertia in the controller's model [-].
    friction_scale : float
        Factor on the viscous damping and Coulomb friction the controller cancels [-].
    """

    mass_scale: float = 1.0
    friction_scale: float = 1.0

    def __post_init__(self) -> None:
        for name in ("mass_scale", "friction_scale"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")


class NonlinearityCancellation:
    """The controller's estimate ĝ(q) + Ĉ(q, q̇)q̇ + f̂(q̇) from its own (possibly mismatched) model."""

    def __init__(
        self, robot: Robot, mismatch: ModelMismatch | None = None, stiction_velocity: float = 5e-3
    ) -> None:
        self.mismatch = mismatch or ModelMismatch()
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
        self._damping_list = self.damping.tolist()
        self._coulomb_list = self.coulomb_friction.tolist()
        self._zero = np.zeros(robot.nv)

    def torque(self, q: np.ndarray, v: np.ndarray, tau_mpc: np.ndarray | None = None) -> np.ndarray:
        """Cancellation torque [N·m] at the estimated state (q, q̇), plus ``tau_mpc`` if given.

        ``torque(q, v, u)`` is the commanded τ = u + ĝ + Ĉq̇ + f̂ in one pass (the loop's form).
        """
        bias = pin.rnea(self.model, self.data, q, v, self._zero).tolist()
        u = self._zero if tau_mpc is None else tau_mpc
        if u.shape != self._zero.shape or v.shape != self._zero.shape:
            raise ValueError(f"v and tau_mpc must have shape {self._zero.shape}")
        inv_vs, tanh = self._inv_stiction, math.tanh
        return np.array([  # floats, zip without strict= (shapes checked): see ArmPlant
            t + b + d * x + c * tanh(x * inv_vs)
            for t, b, d, c, x in zip(u.tolist(), bias, self._damping_list, self._coulomb_list,
                                     v.tolist())
        ])
