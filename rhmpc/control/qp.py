"""The MPC's condensed, move-blocked QP: formulated once with CasADi, extracted as numpy data.

The states are eliminated (``x_k`` is an affine function of ``x0`` and the inputs) and the
inputs are held over move blocks, so the decision vector is the block inputs, normalised by the
torque bounds::

    u_k = u_max ∘ ẑ_{b(k)},   ẑ ∈ [−1, 1]^{nu·nb}

The parameter vector is ``p = [x0 (nx); r_1..r_N (N·ny, point after point); u_{−1} (nu)]``.
The QP, in OSQP's form, is::

    min ½ ẑᵀ P ẑ + q(p)ᵀ ẑ   s.t.   l(p) ≤ A ẑ ≤ u(p),
    q(p) = F p + f0,   l(p) = l0 − G p,   u(p) = u0 − G p

CasADi builds the cost and constraints symbolically (``x_{k+1} = A x_k + B u_k`` rolled out over
the horizon) and its Hessian/Jacobians give ``P``, ``F``, ``f0``, ``A``, ``G`` once, at build
time; nothing here runs per tick.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.linalg

from rhmpc.control.settings import MPCSettings
from robots.linearize import LinearArm


@dataclass(frozen=True, eq=False)
class CondensedQP:
    """Numeric data of the condensed QP (see the module docstring for the equations).

    Attributes
    ----------
    P : (nz, nz) constant Hessian of the cost in the normalised inputs ẑ [-]
    F, f0 : (nz, npar), (nz,) affine map p → q [-]
    A : (m, nz) constraint matrix; its first nz rows are the identity (the torque bounds) [-]
    G : (m, npar) parameter part of the constraint rows; l = l0 − G p, u = u0 − G p
    l0, u0 : (m,) constant parts of the bounds [-]
    param_bounds : bool
        True when some bound depends on p (joint position bounds); else l and u are constant.
    u_max : (nu,) MPC torque bounds [N·m]
    scale : (nz,) u_max tiled over the blocks: z = scale ∘ ẑ [N·m]
    blocking : (N·nu, nz) input sequence from the normalised block inputs, u = blocking @ ẑ [N·m]
    block_of_tick : (N,) block index of each tick
    shift : (nz, nz) ẑ of the plan shifted by one tick (projected back onto the blocks)
    shift_dual : (m, m) the same shift applied to the constraint multipliers
    minimiser : (nz, npar + 1)
        the unconstrained minimiser ẑ* = −P⁻¹ q(p) = minimiser @ [p; 1] [-]
    gain, gain0 : (nu, npar), (nu,)
        first input of the unconstrained minimiser, u0 = gain p + gain0 [N·m]
    terminal_weight : (nx, nx) | None
        P_∞ − CᵀQ_N C when ``terminal == "dare"`` [-]
    """

    P: np.ndarray
    F: np.ndarray
    f0: np.ndarray
    A: np.ndarray
    G: np.ndarray
    l0: np.ndarray
    u0: np.ndarray
    param_bounds: bool
    u_max: np.ndarray
    scale: np.ndarray
    blocking: np.ndarray
    block_of_tick: np.ndarray
    shift: np.ndarray
    shift_dual: np.ndarray
    minimiser: np.ndarray
    gain: np.ndarray
    gain0: np.ndarray
    terminal_weight: np.ndarray | None
    N: int
    nx: int
    nu: int
    ny: int

    @property
    def nz(self) -> int:
        return self.P.shape[0]

    @property
    def npar(self) -> int:
        return self.F.shape[1]

    def q(self, p: np.ndarray) -> np.ndarray:
        """Linear cost term q(p) = F p + f0."""
        return self.F @ p + self.f0

    def bounds(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Constraint bounds (l(p), u(p))."""
        g = self.G @ p
        return self.l0 - g, self.u0 - g

    def params(self, x: np.ndarray, ref: np.ndarray, u_prev: np.ndarray) -> np.ndarray:
        """Parameter vector p = [x0; r_1..r_N; u_{−1}]."""
        return np.concatenate([np.ravel(x), np.ravel(ref), np.ravel(u_prev)])

    def inputs(self, zhat: np.ndarray) -> np.ndarray:
        """Input sequence (N, nu) [N·m] of a normalised block solution ẑ."""
        return (self.blocking @ zhat).reshape(self.N, self.nu)


def _check_arm(arm: LinearArm) -> None:
    nx, nu, ny = arm.nx, arm.nu, arm.ny
    shapes = {
        "A": (arm.A, (nx, nx)), "B": (arm.B, (nx, nu)), "C": (arm.C, (ny, nx)),
        "y0": (arm.y0, (ny,)), "torque_limit": (arm.torque_limit, (nu,)),
    }
    for name, (value, shape) in shapes.items():
        value = np.asarray(value)
        if value.shape != shape:
            raise ValueError(f"arm.{name} must have shape {shape}, got {value.shape}")
        if not np.all(np.isfinite(value)):
            raise ValueError(f"arm.{name} has non-finite entries")
    if nx != 2 * nu:
        raise ValueError(f"expected x = [q − q0; q̇] with nx = 2·nu, got nx={nx}, nu={nu}")
    if np.any(np.asarray(arm.torque_limit) <= 0):
        raise ValueError(f"torque limits must be > 0, got {arm.torque_limit}")


def build_condensed_qp(arm: LinearArm, settings: MPCSettings) -> CondensedQP:
    """Formulate the MPC QP with CasADi and extract its numeric data.

    Raises
    ------
    ValueError
        If the arm's data are malformed or the settings do not fit the arm (torque bounds ≤ 0,
        joint bounds of the wrong length or excluding q0, a singular Hessian, …).
    """
    _check_arm(arm)
    s = settings
    A, B, C = (np.asarray(m, dtype=float) for m in (arm.A, arm.B, arm.C))
    y0 = np.asarray(arm.y0, dtype=float)
    nx, nu, ny, N = arm.nx, arm.nu, arm.ny, s.horizon
    nq = nx // 2
    u_max = (1.0 - s.torque_margin) * np.asarray(arm.torque_limit, dtype=float)
    if not np.all(u_max > 0):
        raise ValueError(f"MPC torque bounds must be > 0, got {u_max}")

    blocks = s.block_lengths
    nb = len(blocks)
    nz = nu * nb
    block_of_tick = np.repeat(np.arange(nb), blocks)
    blocking = np.zeros((N * nu, nz))
    for k, b in enumerate(block_of_tick):
        blocking[k * nu:(k + 1) * nu, b * nu:(b + 1) * nu] = np.diag(u_max)
    block_ends = np.cumsum(blocks)  # tick index k+1 of the state at each block's end

    w = np.ones(N) if s.point_weights is None else np.asarray(s.point_weights, dtype=float)
    q_scale = s.tracking_weight / s.position_scale**2
    R = s.effort_weight * np.diag(1.0 / u_max**2)
    R_d = s.rate_weight * np.diag(1.0 / u_max**2)

    terminal_weight = None
    if s.terminal == "dare":
        if s.effort_weight <= 0:
            raise ValueError("terminal='dare' needs effort_weight > 0 (R positive definite)")
        Qx = C.T @ (q_scale * w[-1] * np.eye(ny)) @ C
        P_inf = scipy.linalg.solve_discrete_are(A, B, Qx, R)
        terminal_weight = 0.5 * ((P_inf - Qx) + (P_inf - Qx).T)
        Cq_pinv = np.linalg.pinv(C[:, :nq])

    q_lo = q_hi = None
    if s.joint_lower is not None:
        if len(s.joint_lower) != nq:
            raise ValueError(f"joint bounds must have {nq} entries, got {len(s.joint_lower)}")
        q_lo = np.asarray(s.joint_lower, dtype=float) - arm.q0
        q_hi = np.asarray(s.joint_upper, dtype=float) - arm.q0
        if np.any(q_lo > 0) or np.any(q_hi < 0):
            raise ValueError("the joint bounds must contain the linearisation posture q0")

    # -- symbolic formulation ----------------------------------------------------------------
    npar = nx + N * ny + nu
    z = ca.SX.sym("z", nz)
    p = ca.SX.sym("p", npar)
    x = p[:nx]
    r = ca.reshape(p[nx:nx + N * ny], ny, N)  # column k = r_{k+1}
    u_prev = p[nx + N * ny:]
    u_seq = ca.mtimes(ca.DM(blocking), z)
    Ad, Bd, Cd, Rd, R_dd = ca.DM(A), ca.DM(B), ca.DM(C), ca.DM(R), ca.DM(R_d)
    cost = 0
    q_rows = []
    for k in range(N):
        u = u_seq[k * nu:(k + 1) * nu]
        du = u - u_prev
        cost += ca.bilin(Rd, u, u) + ca.bilin(R_dd, du, du)
        x = ca.mtimes(Ad, x) + ca.mtimes(Bd, u)
        e = ca.mtimes(Cd, x) + ca.DM(y0) - r[:, k]
        cost += q_scale * w[k] * ca.dot(e, e)
        if q_lo is not None and (k + 1) in block_ends:
            q_rows.append(x[:nq])
        u_prev = u
    if terminal_weight is not None:
        x_ss = ca.vertcat(ca.mtimes(ca.DM(Cq_pinv), r[:, N - 1] - ca.DM(y0)), ca.DM.zeros(nq))
        cost += ca.bilin(ca.DM(terminal_weight), x - x_ss, x - x_ss)
    g = ca.vertcat(z, *q_rows)

    hess, grad = ca.hessian(cost, z)
    outputs = [hess, ca.jacobian(grad, p), grad, ca.jacobian(g, z), ca.jacobian(g, p), g]
    extract = ca.Function("extract", [z, p], outputs)
    values = extract(np.zeros(nz), np.zeros(npar))
    H, F, f0, Acon, G, g0 = (np.array(v, dtype=float) for v in values)
    H = 0.5 * (H + H.T)
    f0, g0 = f0.ravel(), g0.ravel()
    if not (np.all(np.isfinite(H)) and np.all(np.isfinite(F)) and np.all(np.isfinite(f0))):
        raise ValueError("the QP data are not finite; check the weights and the arm")

    lb = [-np.ones(nz)]
    ub = [np.ones(nz)]
    if q_rows:
        lb.append(np.tile(q_lo, len(q_rows)))
        ub.append(np.tile(q_hi, len(q_rows)))
    l0 = np.concatenate(lb) - g0
    u0 = np.concatenate(ub) - g0
    # Joint-bound rows (rad per normalised input, ~1e-4…1e-2) are scaled to unit norm like the
    # torque rows, so that one ADMM step size rho suits every constraint.
    row_scale = np.ones(len(l0))
    row_scale[nz:] = 1.0 / np.maximum(np.linalg.norm(Acon[nz:], axis=1), 1e-12)
    Acon, G = Acon * row_scale[:, None], G * row_scale[:, None]
    l0, u0 = l0 * row_scale, u0 * row_scale

    # -- unconstrained minimiser (the fallback gain) ---------------------------------------------
    try:
        chol = scipy.linalg.cho_factor(H)
    except np.linalg.LinAlgError:
        raise ValueError(
            "the QP Hessian is not positive definite; raise effort_weight or rate_weight"
        ) from None
    Z = -scipy.linalg.cho_solve(chol, np.column_stack([F, f0]))
    gain = u_max[:, None] * Z[:nu, :-1]
    gain0 = u_max * Z[:nu, -1]

    # -- one-tick shift of a blocked plan, projected back onto the blocks ----------------------
    S_b = np.zeros((nb, nb))
    for k in range(N):
        S_b[block_of_tick[k], block_of_tick[min(k + 1, N - 1)]] += 1.0
    S_b /= np.asarray(blocks, dtype=float)[:, None]
    shift = np.kron(S_b, np.eye(nu))
    m = Acon.shape[0]
    shift_dual = np.zeros((m, m))
    shift_dual[:nz, :nz] = shift
    if q_rows:
        shift_dual[nz:, nz:] = np.kron(S_b, np.eye(nq))

    return CondensedQP(
        P=H, F=F, f0=f0, A=Acon, G=G, l0=l0, u0=u0, param_bounds=bool(np.any(G != 0)),
        u_max=u_max, scale=np.tile(u_max, nb), blocking=blocking, block_of_tick=block_of_tick,
        shift=shift, shift_dual=shift_dual, minimiser=Z, gain=gain, gain0=gain0,
        terminal_weight=terminal_weight, N=N, nx=nx, nu=nu, ny=ny,
    )
