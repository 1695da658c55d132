"""The MPC's model: the arm linearised about its home posture and discretised exactly (ZOH)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from rhmpc.robots.model import Robot


@dataclass(frozen=True, eq=False)
class LinearArm:
    r"""Discrete linear model of the arm about ``q0`` (gravity, Coriolis and friction cancelled).

    Continuous time, with the state :math:`x = [q - q_0;\ \dot q]` [rad, rad/s], the input
    :math:`u = \tau` [N·m] and the end-effector position y [m]:

    .. math::

        \dot x = A_c x + B_c u, \qquad
        A_c = \begin{bmatrix} 0 & I \\ 0 & 0 \end{bmatrix}, \quad
        B_c = \begin{bmatrix} 0 \\ M(q_0)^{-1} \end{bmatrix},

        y = C x + y_0, \qquad C = \begin{bmatrix} J(q_0) & 0 \end{bmatrix}, \quad
        y_0 = p(q_0).

    Discrete time at the sample period :math:`T_s` (zero-order hold on u, :func:`zoh`):

    .. math::

        x^+ = A x + B u, \qquad
        \begin{bmatrix} A & B \\ 0 & I \end{bmatrix}
        = \exp\left(\begin{bmatrix} A_c & B_c \\ 0 & 0 \end{bmatrix} T_s\right).

    Attributes
    ----------
    A : ndarray, shape (2n, 2n)
        Discrete state matrix, [I, Ts·I; 0, I] (the velocity columns in [s]).
    B : ndarray, shape (2n, n)
        Discrete input matrix: rows of q [rad/(N·m)], rows of q̇ [rad/(s·N·m)].
    C : ndarray, shape (3, 2n)
        Output matrix [J(q0), 0] [m/rad].
    y0 : ndarray, shape (3,)
        End-effector position at q0 [m].
    Ac, Bc : ndarray
        The continuous-time matrices; the lower block of Bc is M(q0)⁻¹ [1/(kg·m²)].
    q0 : ndarray, shape (n,)
        Linearisation posture [rad].
    M0 : ndarray, shape (n, n)
        Joint-space inertia at q0, armature included [kg·m²].
    Ts : float
        Sample period [s].
    torque_limit : ndarray, shape (n,)
        Actuator saturation [N·m].
    robot : Robot or None
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
