"""The MPC's condensed, move-blocked QP: formulated once with CasADi, extracted as numpy data.

The states are eliminated (``x_k`` is an affine function of ``x0`` and the inputs) and the
inputs are held over move blocks. The decision vector is the block inputs normalised by the
torque bounds, followed by the envelope's slacks (:mod:`rhmpc.control.envelope`)::

    v = [ẑ (nz); s (ns)],   u_k = u_max ∘ ẑ_{b(k)},   ẑ ∈ [−1, 1]^{nu·nb},   s ≥ 0

The parameter vector is ``p = [x0 (nx); r_1..r_N (N·ny, point after point); u_{−1} (nu);
d (ny)]``, with ``d`` the output offset: the model's output is ``y_k = C x_k + y0 + d``
(offset-free MPC; ``d = p(q̂) − (C x̂ + y0)`` is measured each tick by forward kinematics).
The QP, in OSQP's form, is::

    min ½ vᵀ P v + q(p)ᵀ v   s.t.   l(p) ≤ A v ≤ u(p),
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

from rhmpc.control.envelope import EnvelopeRows, envelope_rows
from rhmpc.control.settings import MPCSettings
from robots.linearize import LinearArm


@dataclass(frozen=True, eq=False)
class CondensedQP:
    """Numeric data of the condensed QP (see the module docstring for the equations).

    The per-tick update is affine in the parameters and nothing else changes::

        p = [x (nx); r_1..r_N (N·ny); u_{−1} (nu); d (ny)]          (npar = nx + N·ny + nu + ny)
        q = F p + f0                  F: (nv, npar), f0: (nv,)
        l = l0 − G p,  u = u0 − G p   G: (m, npar), l0, u0: (m,)  (±inf entries stay infinite)

    with ``P`` (nv, nv) and ``A`` (m, nv) fixed. Only the columns ``G[:, bound_columns]`` are
    non-zero (the state and the offset), so ``G p = G[:, bound_columns] p[bound_columns]``.
    The rows of ``A`` are: ``nz`` torque rows (identity on ẑ, bounds ±1), ``ns`` slack rows
    (identity on s, bounds [0, inf)), then the envelope rows, block after block.

    Attributes
    ----------
    P : (nv, nv) constant Hessian of the cost [-]
    F, f0 : (nv, npar), (nv,) affine map p → q [-]
    A : (m, nv) constraint matrix [-]
    G : (m, npar) parameter part of the constraint rows; l = l0 − G p, u = u0 − G p
    l0, u0 : (m,) constant parts of the bounds [-]
    param_bounds : bool
        True when some bound depends on p (an envelope is on); else l and u are constant.
    bound_columns : (k,) indices of the non-zero columns of G
    u_max : (nu,) MPC torque bounds [N·m]
    scale : (nz,) u_max tiled over the blocks: z = scale ∘ ẑ [N·m]
    blocking : (N·nu, nz) input sequence from the normalised block inputs, u = blocking @ ẑ [N·m]
    block_of_tick : (N,) block index of each tick
    shift : (nv, nv) v of the plan shifted by one tick (projected back onto the blocks; slacks
        kept)
    shift_dual : (m, m) the same shift applied to the constraint multipliers
    minimiser : (nv, npar + 1)
        the screening candidate [ẑ*; 0] = minimiser @ [p; 1], ẑ* the unconstrained minimiser
        over ẑ with s = 0 [-]
    gain, gain0 : (nu, npar), (nu,)
        first input of the unconstrained minimiser, u0 = gain p + gain0 [N·m]
    terminal_weight : (nx, nx) | None
        P_∞ − CᵀQ_N C when ``terminal == "dare"`` [-]
    envelope : EnvelopeRows
        The envelope's rows per block end (directions, bounds, slack groups).
    slack_names : tuple[str, ...]
        Name of each slack (``"position[0]"``, ``"velocity[2]"``, ``"cartesian"``).
    """

    P: np.ndarray
    F: np.ndarray
    f0: np.ndarray
    A: np.ndarray
    G: np.ndarray
    l0: np.ndarray
    u0: np.ndarray
    param_bounds: bool
    bound_columns: np.ndarray
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
    envelope: EnvelopeRows
    slack_names: tuple[str, ...]
    N: int
    nx: int
    nu: int
    ny: int
    nz: int

    @property
    def ns(self) -> int:
        """Number of slacks."""
        return len(self.slack_names)

    @property
    def nv(self) -> int:
        """Number of decision variables nz + ns."""
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

    def params(
        self, x: np.ndarray, ref: np.ndarray, u_prev: np.ndarray, offset: np.ndarray | None = None
    ) -> np.ndarray:
        """Parameter vector p = [x0; r_1..r_N; u_{−1}; d] (d defaults to 0)."""
        d = np.zeros(self.ny) if offset is None else np.ravel(offset)
        return np.concatenate([np.ravel(x), np.ravel(ref), np.ravel(u_prev), d])

    def inputs(self, v: np.ndarray) -> np.ndarray:
        """Input sequence (N, nu) [N·m] of a normalised block solution ẑ (or v = [ẑ; s])."""
        return (self.blocking @ v[: self.nz]).reshape(self.N, self.nu)


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
    env = envelope_rows(arm, s, u_max)

    blocks = s.block_lengths
    nb = len(blocks)
    nz = nu * nb
    ns = env.ns
    nv = nz + ns
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

    # -- symbolic formulation ----------------------------------------------------------------
    npar = nx + N * ny + nu + ny
    z = ca.SX.sym("z", nz)
    p = ca.SX.sym("p", npar)
    x = p[:nx]
    r = ca.reshape(p[nx:nx + N * ny], ny, N)  # column k = r_{k+1}
    u_prev = p[nx + N * ny:nx + N * ny + nu]
    d = p[nx + N * ny + nu:]
    u_seq = ca.mtimes(ca.DM(blocking), z)
    Ad, Bd, Cd, Rd, R_dd = ca.DM(A), ca.DM(B), ca.DM(C), ca.DM(R), ca.DM(R_d)
    Dq, Dv, Dy = ca.DM(env.Dq), ca.DM(env.Dv), ca.DM(env.Dy)
    cost = 0
    env_rows = []
    for k in range(N):
        u = u_seq[k * nu:(k + 1) * nu]
        du = u - u_prev
        cost += ca.bilin(Rd, u, u) + ca.bilin(R_dd, du, du)
        x = ca.mtimes(Ad, x) + ca.mtimes(Bd, u)
        y_rel = ca.mtimes(Cd, x) + d  # y − y0
        e = y_rel + ca.DM(y0) - r[:, k]
        cost += q_scale * w[k] * ca.dot(e, e)
        if env.m and (k + 1) in block_ends:
            env_rows.append(ca.mtimes(Dq, x[:nq]) + ca.mtimes(Dv, x[nq:]) + ca.mtimes(Dy, y_rel))
        u_prev = u
    if terminal_weight is not None:
        x_ss = ca.vertcat(ca.mtimes(ca.DM(Cq_pinv), r[:, N - 1] - ca.DM(y0) - d),
                          ca.DM.zeros(nq))
        cost += ca.bilin(ca.DM(terminal_weight), x - x_ss, x - x_ss)
    g = ca.vertcat(*env_rows) if env_rows else ca.SX.zeros(0, 1)

    hess, grad = ca.hessian(cost, z)
    outputs = [hess, ca.jacobian(grad, p), grad, ca.jacobian(g, z), ca.jacobian(g, p), g]
    extract = ca.Function("extract", [z, p], outputs)
    values = extract(np.zeros(nz), np.zeros(npar))
    H, F, f0, Jz, Jp, g0 = (np.array(v, dtype=float) for v in values)
    H = 0.5 * (H + H.T)
    f0, g0 = f0.ravel(), g0.ravel()
    if not (np.all(np.isfinite(H)) and np.all(np.isfinite(F)) and np.all(np.isfinite(f0))):
        raise ValueError("the QP data are not finite; check the weights and the arm")
    try:
        chol = scipy.linalg.cho_factor(H)
    except np.linalg.LinAlgError:
        raise ValueError(
            "the QP Hessian is not positive definite; raise effort_weight or rate_weight"
        ) from None

    # -- the soft envelope: slacks, rows, bounds -------------------------------------------------
    Amat, G, l0, u0 = _constraints(env, Jz.reshape(-1, nz), Jp.reshape(-1, npar), g0, blocks,
                                   arm.Ts, nz)
    P = scipy.linalg.block_diag(H, s.envelope_quadratic * np.eye(ns))
    F_all = np.vstack([F, np.zeros((ns, npar))])
    f0_all = np.concatenate([f0, np.full(ns, s.envelope_penalty)])

    # -- unconstrained minimiser over ẑ with s = 0 (screening, LQ fallback) ----------------------
    Z = np.zeros((nv, npar + 1))
    Z[:nz] = -scipy.linalg.cho_solve(chol, np.column_stack([F, f0]))
    gain = u_max[:, None] * Z[:nu, :-1]
    gain0 = u_max * Z[:nu, -1]

    # -- one-tick shift of a blocked plan, projected back onto the blocks ----------------------
    S_b = np.zeros((nb, nb))
    for k in range(N):
        S_b[block_of_tick[k], block_of_tick[min(k + 1, N - 1)]] += 1.0
    S_b /= np.asarray(blocks, dtype=float)[:, None]
    shift = scipy.linalg.block_diag(np.kron(S_b, np.eye(nu)), np.eye(ns))
    m = Amat.shape[0]
    shift_dual = np.zeros((m, m))
    shift_dual[:nv, :nv] = shift
    if env.m:
        shift_dual[nv:, nv:] = np.kron(S_b, np.eye(2 * env.m))

    cols = np.flatnonzero(np.any(G != 0, axis=0))
    return CondensedQP(
        P=P, F=F_all, f0=f0_all, A=Amat, G=G, l0=l0, u0=u0, param_bounds=bool(cols.size),
        bound_columns=cols, u_max=u_max, scale=np.tile(u_max, nb), blocking=blocking,
        block_of_tick=block_of_tick, shift=shift, shift_dual=shift_dual, minimiser=Z,
        gain=gain, gain0=gain0, terminal_weight=terminal_weight, envelope=env,
        slack_names=env.names, N=N, nx=nx, nu=nu, ny=ny, nz=nz,
    )


def _constraints(
    env: EnvelopeRows, Jz: np.ndarray, Jp: np.ndarray, g0: np.ndarray, blocks, Ts: float,
    nz: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A, G, l0, u0: torque rows, slack rows, then per block end the upper and lower envelope
    rows ``c·x_k − s ≤ hi − margin`` and ``c·x_k + s ≥ lo + margin`` (margin = curvature·T²/8).
    """
    ns, me = env.ns, env.m
    nv = nz + ns
    nb = len(blocks)
    m = nv + 2 * me * nb
    A = np.zeros((m, nv))
    A[:nv, :nv] = np.eye(nv)
    G = np.zeros((m, Jp.shape[1]))
    l0 = np.concatenate([-np.ones(nz), np.zeros(ns), np.zeros(m - nv)])
    u0 = np.concatenate([np.ones(nz), np.full(ns, np.inf), np.zeros(m - nv)])
    for b in range(nb):
        margin = env.curvature * (blocks[b] * Ts) ** 2 / 8.0
        src = slice(b * me, (b + 1) * me)
        up = slice(nv + 2 * b * me, nv + (2 * b + 1) * me)
        lo = slice(nv + (2 * b + 1) * me, nv + (2 * b + 2) * me)
        for rows, sign in ((up, -1.0), (lo, 1.0)):
            A[rows, :nz] = Jz[src]
            A[np.arange(rows.start, rows.stop), nz + env.slack] = sign  # the row's slack
            G[rows] = Jp[src]
        u0[up] = env.hi - margin - g0[src]
        l0[up] = -np.inf
        l0[lo] = env.lo + margin - g0[src]
        u0[lo] = np.inf
    # Envelope rows are scaled to unit norm (in [ẑ; s]) like the torque rows, so that one ADMM
    # step size rho suits every constraint.
    row_scale = np.ones(m)
    row_scale[nv:] = 1.0 / np.linalg.norm(A[nv:], axis=1)
    return A * row_scale[:, None], G * row_scale[:, None], l0 * row_scale, u0 * row_scale
