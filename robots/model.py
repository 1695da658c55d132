"""The `Robot`: a Pinocchio model plus what the controller needs to know about the hardware."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin


@dataclass(frozen=True, eq=False)
class Robot:
    """A fixed-base arm whose end-effector position is controlled.

    The model is kept apart from its work data (Pinocchio style): create one ``pin.Data`` per
    user with :meth:`create_data`; the helpers below use a private one and are not thread-safe.

    Attributes
    ----------
    name : str
        Registry name.
    model : pinocchio.Model
        Kinematics and rigid-body dynamics; ``model.armature`` [kg·m²], ``model.damping``
        [N·m·s/rad] and ``model.friction`` (Coulomb) [N·m] hold the actuator data.
    ee_frame : str
        Name of the end-effector frame whose origin is the controlled point.
    q0 : numpy.ndarray
        Home posture [rad]; the MPC's linearisation point.
    torque_limit : numpy.ndarray
        Actuator saturation per joint [N·m].
    encoder_resolution : numpy.ndarray | None
        Joint angle per encoder count [rad], or None when the robot has no encoder model.
    description : str
        One line on where the model comes from.
    """

    name: str
    model: pin.Model
    ee_frame: str
    q0: np.ndarray
    torque_limit: np.ndarray
    encoder_resolution: np.ndarray | None = None
    description: str = ""
    _data: pin.Data = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.model.existFrame(self.ee_frame):
            raise ValueError(f"robot {self.name!r}: no frame {self.ee_frame!r} in the model")
        object.__setattr__(self, "q0", np.asarray(self.q0, dtype=float).copy())
        object.__setattr__(self, "torque_limit", np.asarray(self.torque_limit, dtype=float).copy())
        object.__setattr__(self, "_data", self.model.createData())
        self.check_posture(self.q0)
        if self.torque_limit.shape != (self.nv,) or np.any(self.torque_limit <= 0):
            raise ValueError(
                f"robot {self.name!r}: torque limits must be {self.nv} positive values"
            )

    # -- sizes and data --------------------------------------------------------------------
    @property
    def nq(self) -> int:
        return self.model.nq

    @property
    def nv(self) -> int:
        return self.model.nv

    @property
    def ee_frame_id(self) -> int:
        return self.model.getFrameId(self.ee_frame)

    @property
    def armature(self) -> np.ndarray:
        """Reflected rotor inertia per joint [kg·m²]."""
        return np.asarray(self.model.armature).copy()

    @property
    def damping(self) -> np.ndarray:
        """Viscous joint damping [N·m·s/rad]."""
        return np.asarray(self.model.damping).copy()

    @property
    def coulomb_friction(self) -> np.ndarray:
        """Coulomb joint friction [N·m]."""
        return np.asarray(self.model.friction).copy()

    @property
    def position_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper joint limits [rad]."""
        return (
            np.asarray(self.model.lowerPositionLimit).copy(),
            np.asarray(self.model.upperPositionLimit).copy(),
        )

    @property
    def velocity_limit(self) -> np.ndarray:
        """Joint speed limits [rad/s] (the URDF's ``<limit velocity=…>``)."""
        return np.asarray(self.model.velocityLimit).copy()

    def create_data(self) -> pin.Data:
        """Fresh Pinocchio work data for this model."""
        return self.model.createData()

    # -- kinematics ------------------------------------------------------------------------
    def check_posture(self, q: np.ndarray) -> np.ndarray:
        """Return ``q`` as floats; ``ValueError`` if it is malformed or outside the joint limits."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.nq,):
            raise ValueError(
                f"robot {self.name!r}: posture must have shape ({self.nq},), got {q.shape}"
            )
        if not np.all(np.isfinite(q)):
            raise ValueError(f"robot {self.name!r}: posture has non-finite values: {q}")
        lower, upper = self.position_limits
        outside = (q < lower - 1e-12) | (q > upper + 1e-12)
        if np.any(outside):
            j = int(np.flatnonzero(outside)[0])
            lo, hi, at = np.degrees([lower[j], upper[j], q[j]])
            raise ValueError(
                f"robot {self.name!r}: joint {self.model.names[j + 1]!r} at {at:.1f} deg "
                f"is outside its limits [{lo:.1f}, {hi:.1f}] deg"
            )
        return q

    def ee_position(self, q: np.ndarray) -> np.ndarray:
        """End-effector position p(q) in the world frame [m]."""
        pin.framesForwardKinematics(self.model, self._data, q)
        return self._data.oMf[self.ee_frame_id].translation.copy()

    def ee_jacobian(self, q: np.ndarray) -> np.ndarray:
        """Translational Jacobian ∂p/∂q of the end-effector in world-aligned axes, shape (3, nv)."""
        J = pin.computeFrameJacobian(
            self.model, self._data, q, self.ee_frame_id, pin.LOCAL_WORLD_ALIGNED
        )
        return J[:3].copy()

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Joint-space inertia M(q) including armature [kg·m²] (CRBA, symmetrised)."""
        M = pin.crba(self.model, self._data, q)
        return np.triu(M) + np.triu(M, 1).T
