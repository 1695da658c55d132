"""The `Robot`: a Pinocchio model plus what the controller needs to know about the hardware."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin
import scipy.linalg


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
        Kinematics and rigid-body dynamics; ``model.armature`` [kg·m²] holds reflected rotor
        inertia, ``model.damping`` [N·m·s/rad] and ``model.friction`` (Coulomb) [N·m] the
        friction of each motor, acting on its output coordinate (``motor_map``).
    ee_frame : str
        Name of the end-effector frame whose origin is the controlled point.
    q0 : numpy.ndarray
        Home posture [rad]; the MPC's linearisation point.
    torque_limit : numpy.ndarray
        Actuator saturation per joint [N·m].
    encoder_resolution : numpy.ndarray | None
        Angle per encoder count of each motor's output coordinate ``S q`` [rad], or None when
        the robot has no encoder model.
    description : str
        One line on where the model comes from.
    motor_map : numpy.ndarray | None
        ``S`` (n, n): the motors' output angles are ``θ = S (q − q0)`` (the angles the drives
        turn, each motor through its transmission), rates ``ω = S q̇``; None: ``S = I``, each
        joint its own motor. Friction acts on ``θ`` and the encoders count it.
    gear_ratio : numpy.ndarray | None
        Transmission ratio η of each motor, motor angle = η θ [-]; None when unknown.
    rotor_inertia : numpy.ndarray | None
        Reflected rotor inertia η² J_m of each motor, on its output coordinate [kg·m²]; it is
        part of the model's M(q) as ``Sᵀ diag(η² J_m) S`` (the registry adds it). None: zero.
    coupling : tuple
        Linear joint limits beyond the box: ``(c, lo, hi)`` rows, ``lo ≤ c·q ≤ hi`` [rad].
    """

    name: str
    model: pin.Model
    ee_frame: str
    q0: np.ndarray
    torque_limit: np.ndarray
    encoder_resolution: np.ndarray | None = None
    description: str = ""
    motor_map: np.ndarray | None = None
    gear_ratio: np.ndarray | None = None
    rotor_inertia: np.ndarray | None = None
    coupling: tuple = ()
    _data: pin.Data = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if not self.model.existFrame(self.ee_frame):
            raise ValueError(f"robot {self.name!r}: no frame {self.ee_frame!r} in the model")
        object.__setattr__(self, "q0", np.asarray(self.q0, dtype=float).copy())
        object.__setattr__(self, "torque_limit", np.asarray(self.torque_limit, dtype=float).copy())
        object.__setattr__(self, "_data", self.model.createData())
        S = np.eye(self.nv) if self.motor_map is None else np.asarray(self.motor_map, float)
        if S.shape != (self.nv, self.nv) or abs(np.linalg.det(S)) < 1e-9:
            raise ValueError(f"robot {self.name!r}: motor_map must be an invertible "
                             f"{self.nv}x{self.nv} matrix")
        object.__setattr__(self, "motor_map", S)
        rotor = np.zeros(self.nv) if self.rotor_inertia is None else self.rotor_inertia
        object.__setattr__(self, "rotor_inertia", np.broadcast_to(
            np.asarray(rotor, dtype=float), (self.nv,)).copy())
        object.__setattr__(self, "coupling", tuple(
            (np.asarray(c, dtype=float), float(lo), float(hi)) for c, lo, hi in self.coupling))
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
        """Viscous friction of each motor on its output coordinate [N·m·s/rad]."""
        return np.asarray(self.model.damping).copy()

    @property
    def coulomb_friction(self) -> np.ndarray:
        """Coulomb friction of each motor on its output coordinate [N·m]."""
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
        for c, lo, hi in self.coupling:
            value = float(c @ q)
            if not lo - 1e-12 <= value <= hi + 1e-12:
                raise ValueError(
                    f"robot {self.name!r}: coupled limit {np.degrees(lo):.1f} ≤ {c.tolist()}·q ≤ "
                    f"{np.degrees(hi):.1f} deg violated ({np.degrees(value):.1f} deg)"
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

    def clamp(self, q: np.ndarray) -> np.ndarray:
        """``q`` moved into the joint limits: the box, then each coupled limit c·q ∈ [lo, hi]
        by the least change along c (projections in turn, repeated a few times)."""
        lower, upper = self.position_limits
        q = np.clip(q, lower, upper)
        for _ in range(4):
            for c, lo, hi in self.coupling:
                value = float(c @ q)
                if not lo <= value <= hi:
                    q = q + (min(max(value, lo), hi) - value) * c / float(c @ c)
            q = np.clip(q, lower, upper)
        return q

    def distance_to_reach(self, point: np.ndarray, q: np.ndarray | None = None,
                          iterations: int = 60) -> tuple[float, np.ndarray]:
        """How far ``point`` [m] lies from the end-effector positions the joint limits allow,
        and the posture that comes closest: projected Gauss–Newton on ‖p(q) − point‖² from
        ``q`` (default home), each step q ← clamp(q + J⁺ (point − p(q))), damped. A local
        search: a distance of 0 proves the point reachable; a positive one is an upper bound
        of the true distance [m]."""
        q = self.q0.copy() if q is None else np.asarray(q, dtype=float)
        best = (np.inf, q)
        for _ in range(iterations):
            miss = np.asarray(point, dtype=float) - self.ee_position(q)
            distance = float(np.linalg.norm(miss))
            if distance < best[0]:
                best = (distance, q)
            if distance < 1e-7:
                break
            J = self.ee_jacobian(q)
            step = J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(3), miss)
            q = self.clamp(q + step)
        return best

    def mass_matrix(self, q: np.ndarray) -> np.ndarray:
        """Joint-space inertia M(q) including armature [kg·m²] (CRBA, symmetrised)."""
        M = pin.crba(self.model, self._data, q)
        return np.triu(M) + np.triu(M, 1).T

    @property
    def has_mimic(self) -> bool:
        """Whether bodies follow the joints through mimic joints (a closed linkage as a tree):
        Pinocchio's ABA does not take such models, :func:`forward_dynamics` does."""
        return self.model.njoints - 1 != self.nv


def forward_dynamics(model: pin.Model, data: pin.Data, q: np.ndarray, v: np.ndarray,
                     tau: np.ndarray) -> np.ndarray:
    """q̈ = M(q)⁻¹ (τ − h(q, q̇)) [rad/s²], M from CRBA and h = C q̇ + g from RNEA(q, q̇, 0).

    Pinocchio's ABA where the model allows it (no mimic joints), else the mass matrix solved by
    Cholesky: the same equation of motion for a linkage whose extra bodies follow the joints.
    """
    if model.njoints - 1 == model.nv:
        return pin.aba(model, data, q, v, tau)
    M = pin.crba(model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    h = pin.nonLinearEffects(model, data, q, v)
    return scipy.linalg.cho_solve(scipy.linalg.cho_factor(M), np.subtract(tau, h))


#: Pinocchio joints about a coordinate axis.
_AXES = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0),
         "JointModelRZ": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class Body:
    """A body of a tree of revolute joints, for code that computes the dynamics itself (the
    plant's compiled kernel, the exported controller's model).

    Its parent (−1 the base), the degree of freedom it follows as qb = scale·q[coord] + offset
    about ``axis`` (unit, body frame; a mimic joint has scale and offset, the PHANToM's
    parallelogram), its joint placement (R, p) in the parent, and its inertia about its origin:
    mass m [kg], first moment h = m c [kg·m] and rotational inertia I_o = I_c + m(cᵀc 1 − c cᵀ)
    [kg·m²] (the parallel-axis theorem)."""

    parent: int
    coord: int
    scale: float
    offset: float
    axis: np.ndarray
    R: np.ndarray
    p: np.ndarray
    mass: float
    h: np.ndarray
    I_o: np.ndarray


def bodies(model: pin.Model) -> list[Body]:
    """The bodies of ``model``, root first; ValueError for a joint that is not revolute (RX, RY,
    RZ, revolute-unaligned, or a mimic of one)."""
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    out = []
    for i, joint in enumerate(model.joints[1:], start=1):
        name = joint.shortname()
        if name in _AXES or name == "JointModelRevoluteUnaligned":
            axis = np.array(_AXES.get(name) or np.asarray(joint.extract().axis), dtype=float)
            coord, scale, offset = joint.idx_v, 1.0, 0.0
        elif name == "JointModelMimic":
            mimic = joint.extract()
            S = np.asarray(data.joints[i].S).reshape(6, -1)[:, 0]  # (linear; angular)
            if np.abs(S[:3]).max() > 0 or mimic.scaling == 0:
                raise ValueError(f"joint {model.names[i]}: a mimic joint that is not "
                                 "revolute")
            axis, coord = S[3:] / mimic.scaling, joint.idx_v
            scale, offset = float(mimic.scaling), float(mimic.offset)
        else:
            raise ValueError(f"joint {model.names[i]} ({name}) is not revolute")
        inertia, placement = model.inertias[i], model.jointPlacements[i]
        c, m = np.asarray(inertia.lever), float(inertia.mass)
        I_o = np.asarray(inertia.inertia) + m * (c @ c * np.eye(3) - np.outer(c, c))
        out.append(Body(int(model.parents[i]) - 1, int(coord), scale, offset, axis,
                        np.asarray(placement.rotation), np.asarray(placement.translation),
                        m, m * c, I_o))
    return out
