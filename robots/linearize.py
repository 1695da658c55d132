"""The MPC's model: the arm linearised about its home posture and discretised exactly (ZOH)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from robots.model import Robot


@dataclass(frozen=True, eq=False)
class LinearArm:
    """Discrete linear model of the arm about ``q0`` (gravity, Coriolis and friction cancelled).

    Continuous time, with ``x = [q − q0; q̇]`` (rad, rad/s), ``u = τ`` (N·m)::

        ẋ = Ac x + Bc u,   Ac = [[0, I], [0, 0]],   Bc = [[0], [M(q0)⁻¹]]
        y = C x + y0,      C = [J(q0), 0],          y0 = p(q0)   (m)

    Discrete time at the sample period ``Ts`` (zero-order hold on ``u``)::

        x⁺ = A x + B u,    [[A, B], [0, I]] = expm([[Ac, Bc], [0, 0]] · Ts)

    Attributes
    ----------
    A : (2n, 2n) discrete state matrix [-, s]
    B : (2n, n) discrete input matrix [rad/(N·m), s·rad/(N·m)... per row block]
    C : (3, 2n) output matrix [m/rad, 0]
    y0 : (3,) end-effector position at q0 [m]
    Ac, Bc : continuous-time matrices [1/s], [1/(kg·m²)]
    q0 : (n,) linearisation posture [rad]
    M0 : (n, n) joint-space inertia at q0 including armature [kg·m²]
    Ts : sample period [s]
    torque_limit : (n,) actuator saturation [N·m]
    robot : Robot | None
        The robot it was made from (forward kinematics for the MPC's output offset, joint limits
        for its envelope); ``None`` for a model given by its matrices only.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    y0: np.ndarray
    Ac: np.ndarray
    Bc: np.ndarray
    q0: np.ndarray
    M0: np.ndarray
    Ts: float
    torque_limit: np.ndarray
    robot: Robot | None = None

    @property
    def nx(self) -> int:
        return self.A.shape[0]

    @property
    def nu(self) -> int:
        return self.B.shape[1]

    @property
    def ny(self) -> int:
        return self.C.shape[0]

    @property
    def position_limits(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The robot's lower and upper joint limits [rad], or None without a robot."""
        return None if self.robot is None else self.robot.position_limits

    @property
    def velocity_limit(self) -> np.ndarray | None:
        """The robot's joint speed limits [rad/s], or None without a robot."""
        return None if self.robot is None else self.robot.velocity_limit

    def output(self, x: np.ndarray) -> np.ndarray:
        """Linearised end-effector position y = C x + y0 [m]."""
        return self.C @ x + self.y0


def zoh(Ac: np.ndarray, Bc: np.ndarray, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation via the matrix exponential of the augmented system."""
    nx, nu = Bc.shape
    aug = np.zeros((nx + nu, nx + nu))
    aug[:nx, :nx] = Ac
    aug[:nx, nx:] = Bc
    Phi = scipy.linalg.expm(aug * Ts)
    return Phi[:nx, :nx], Phi[:nx, nx:]


def linearize(robot: Robot, q0: np.ndarray | None = None, Ts: float = 0.5e-3) -> LinearArm:
    """Linearise ``robot`` about ``q0`` (default: its home posture) and discretise at ``Ts`` [s].

    Raises
    ------
    ValueError
        If ``q0`` is outside the joint limits or ``Ts`` is not a positive finite number.
    """
    if not (np.isfinite(Ts) and Ts > 0):
        raise ValueError(f"sample period Ts must be positive and finite, got {Ts!r}")
    q0 = robot.check_posture(robot.q0 if q0 is None else q0)
    n = robot.nv
    M0 = robot.mass_matrix(q0)
    J = robot.ee_jacobian(q0)
    Ac = np.block([[np.zeros((n, n)), np.eye(n)], [np.zeros((n, n)), np.zeros((n, n))]])
    Bc = np.vstack([np.zeros((n, n)), np.linalg.inv(M0)])
    A, B = zoh(Ac, Bc, Ts)
    C = np.hstack([J, np.zeros((3, n))])
    return LinearArm(
        A=A, B=B, C=C, y0=robot.ee_position(q0), Ac=Ac, Bc=Bc, q0=q0.copy(), M0=M0, Ts=float(Ts),
        torque_limit=robot.torque_limit.copy(), robot=robot,
    )
