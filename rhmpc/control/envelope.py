"""The safety envelope of the MPC: joint position, joint velocity, coupled joint and Cartesian
limits.

Each limit is a linear function of the predicted state, checked at the end of every move block
and *certified in between*: within a block the input is constant, so under the model
(a double integrator per joint, exact ZOH) the velocity is affine in time and the position
quadratic. An affine function on an interval is bounded by its end values, so the velocity
rows at block ends hold at every tick. For a quadratic ``f(t)`` over a block of duration ``T``::

    max_t f(t) ≤ max(f(0), f(T)) + |f̈| T² / 8,

so the position and Cartesian rows are tightened by ``|f̈|_max T_b² / 8`` with
``|f̈|_max = Σ_i |c M0⁻¹|_i u_max,i`` (``c`` the row's direction in joint space).

The limits are soft with an exact L1 penalty: each group (one joint's position, one joint's
velocity, one coupling, the Cartesian set) has a slack ``s ≥ 0`` measured in :data:`units` of
that group, shared by all its rows over the horizon::

    lo − s ≤ c·x_k ≤ hi + s,     cost  ρ₁ s + ½ ρ₂ s²

With ``ρ₁`` above the multiplier of the hard constraint the soft problem has the hard problem's
solution whenever that one is feasible (exact penalty; Fletcher, *Practical Methods of
Optimization*, 2nd ed., §14.3), and it is always feasible.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Slack unit of the joint position and velocity rows: this fraction of the limit's range [-].
RANGE_UNIT = 0.01
#: Slack unit of the Cartesian rows [m].
CARTESIAN_UNIT = 1e-4


@dataclass(frozen=True)
class EnvelopeRows:
    """The envelope as rows ``lo ≤ D_q (q − q0) + D_v q̇ + D_y (y − y0) ≤ hi`` per block end.

    Attributes
    ----------
    Dq, Dv, Dy : (m, nq), (m, nq), (m, 3) row directions, already divided by the unit [1/unit]
    lo, hi : (m,) bounds in units (±inf where one-sided) [-]
    curvature : (m,) ``|f̈|_max`` / unit per s² [1/s²] (0 for velocity rows)
    slack : (m,) slack index of each row
    names : tuple[str, ...] one name per slack (e.g. ``"position[1]"``)
    """

    Dq: np.ndarray
    Dv: np.ndarray
    Dy: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    curvature: np.ndarray
    slack: np.ndarray
    names: tuple[str, ...]

    @property
    def m(self) -> int:
        return len(self.lo)

    @property
    def ns(self) -> int:
        return len(self.names)


def _unit_vector(name: str, v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    n = np.linalg.norm(v)
    if v.shape != (3,) or not np.isfinite(n) or n == 0:
        raise ValueError(f"{name} must be 3 finite numbers, not all zero, got {v!r}")
    return v / n


def envelope_rows(arm, settings, u_max: np.ndarray) -> EnvelopeRows:
    """Envelope rows for ``arm`` (with its robot's limits) and ``settings`` (MPCSettings).

    Raises
    ------
    ValueError
        If joint limits are asked for but unknown, have the wrong length, or exclude q0.
    """
    nq = arm.nx // 2
    Minv = np.linalg.inv(arm.M0)
    acc_bound = np.abs(Minv) @ u_max  # |q̈_j| ≤ this under |u| ≤ u_max [rad/s²]
    J0 = np.asarray(arm.C[:, :nq])
    rows: list[tuple] = []  # (dq, dv, dy, lo, hi, curvature, slack)
    names: list[str] = []
    s = settings
    eye = np.eye(nq)
    if s.joint_envelope:
        lower, upper = _joint_limits(arm, s, nq)
        for j in range(nq):
            unit = RANGE_UNIT * (upper[j] - lower[j])
            names.append(f"position[{j}]")
            rows.append((eye[j] / unit, 0 * eye[j], np.zeros(3), (lower[j] - arm.q0[j]) / unit,
                         (upper[j] - arm.q0[j]) / unit, acc_bound[j] / unit, len(names) - 1))
        vmax = _velocity_limits(arm, s, nq)
        for j in range(nq):
            unit = RANGE_UNIT * 2 * vmax[j]
            names.append(f"velocity[{j}]")
            rows.append((0 * eye[j], eye[j] / unit, np.zeros(3), -vmax[j] / unit,
                         vmax[j] / unit, 0.0, len(names) - 1))
        for k, (c, lo, hi) in enumerate(_couplings(arm)):  # lo ≤ c·q ≤ hi
            unit = RANGE_UNIT * (hi - lo)
            names.append(f"coupling[{k}]")
            rows.append((c / unit, 0 * c, np.zeros(3), (lo - c @ arm.q0) / unit,
                         (hi - c @ arm.q0) / unit, float(np.abs(c @ Minv) @ u_max) / unit,
                         len(names) - 1))
    if s.cartesian != "none":
        point = np.asarray(s.cartesian_point, dtype=float)
        names.append("cartesian")
        k = len(names) - 1
        if s.cartesian == "halfspace":
            n = _unit_vector("cartesian_normal", s.cartesian_normal)
            curv = np.abs(n @ J0 @ Minv) @ u_max / CARTESIAN_UNIT
            rows.append((np.zeros(nq), np.zeros(nq), n / CARTESIAN_UNIT, -np.inf,
                         (n @ point + s.cartesian_depth) / CARTESIAN_UNIT, curv, k))
        else:  # box
            half = np.asarray(s.cartesian_half_width, dtype=float)
            for a in range(3):
                e = np.eye(3)[a]
                curv = np.abs(J0[a] @ Minv) @ u_max / CARTESIAN_UNIT
                rows.append((np.zeros(nq), np.zeros(nq), e / CARTESIAN_UNIT,
                             (point[a] - half[a]) / CARTESIAN_UNIT,
                             (point[a] + half[a]) / CARTESIAN_UNIT, curv, k))
    if not rows:
        z = np.zeros((0, nq))
        return EnvelopeRows(z, z, np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0),
                            np.zeros(0, dtype=int), ())
    cols = list(zip(*rows, strict=True))
    return EnvelopeRows(
        Dq=np.array(cols[0]), Dv=np.array(cols[1]), Dy=np.array(cols[2]),
        lo=np.array(cols[3], dtype=float), hi=np.array(cols[4], dtype=float),
        curvature=np.array(cols[5], dtype=float), slack=np.array(cols[6], dtype=int),
        names=tuple(names),
    )


def _joint_limits(arm, s, nq: int) -> tuple[np.ndarray, np.ndarray]:
    if s.joint_lower is not None:
        lower, upper = np.asarray(s.joint_lower, float), np.asarray(s.joint_upper, float)
        if len(lower) != nq:
            raise ValueError(f"joint bounds must have {nq} entries, got {len(lower)}")
    elif arm.position_limits is not None:
        lower, upper = (np.asarray(v, dtype=float) for v in arm.position_limits)
    else:
        raise ValueError("joint_envelope needs joint limits: the arm has none, set joint_lower")
    if np.any(lower > arm.q0) or np.any(upper < arm.q0):
        raise ValueError("the joint bounds must contain the linearisation posture q0")
    return lower, upper


def _couplings(arm) -> tuple:
    """The robot's linear joint limits beyond the box, ``(c, lo, hi)`` with lo ≤ c·q ≤ hi
    (:attr:`rhmpc.robots.Robot.coupling`, e.g. a parallelogram's), checked to hold at q0
    (:meth:`rhmpc.robots.Robot.check_posture`)."""
    if arm.robot is None or not arm.robot.coupling:
        return ()
    arm.robot.check_posture(arm.q0)
    return arm.robot.coupling


def _velocity_limits(arm, s, nq: int) -> np.ndarray:
    if s.velocity_limit is not None:
        vmax = np.asarray(s.velocity_limit, dtype=float)
        if len(vmax) != nq:
            raise ValueError(f"velocity_limit must have {nq} entries, got {len(vmax)}")
    elif arm.velocity_limit is not None:
        vmax = np.asarray(arm.velocity_limit, dtype=float)
    else:
        raise ValueError("joint_envelope needs velocity limits: the arm has none, set "
                         "velocity_limit")
    return vmax
