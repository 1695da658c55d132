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

import hashlib
from dataclasses import dataclass
from importlib.metadata import version as _version
from pathlib import Path

import numpy as np
import scipy.linalg

from rhmpc import io
from rhmpc.compiled import cached
from rhmpc.control.envelope import EnvelopeRows, envelope_rows
from rhmpc.control.settings import MPCSettings
from rhmpc.robots.linearize import LinearArm


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
    """Formulate the MPC QP with CasADi and extract its numeric data, once per distinct arm,
    settings and formulation (:func:`rhmpc.compiled.cached`, keyed by their hash).

    Raises
    ------
    ValueError
        If the arm's data are malformed or the settings do not fit the arm (torque bounds ≤ 0,
        joint bounds of the wrong length or excluding q0, a singular Hessian, …).
    """
    _check_arm(arm)
    key = hashlib.sha256(repr(settings).encode() + _version("casadi").encode())
    robot = getattr(arm, "robot", None)
    for part in (arm.A, arm.B, arm.C, arm.y0, arm.q0, arm.Ts, arm.M0, arm.torque_limit,
                 arm.position_limits, arm.velocity_limit):
        key.update(b"-" if part is None else np.asarray(part, dtype=float).tobytes())
    for c, lo, hi in getattr(robot, "coupling", None) or ():
        key.update(np.asarray([*c, lo, hi], dtype=float).tobytes())
    for module in ("qp.py", "envelope.py"):
        key.update(io.read_bytes(Path(__file__).with_name(module), track=False))
    return cached(CondensedQP, "qp", key.hexdigest(), lambda: _formulate(arm, settings))


def _formulate(arm: LinearArm, settings: MPCSettings) -> CondensedQP:
    """The QP's data (:func:`build_condensed_qp`)."""
    s = settings
    nx, nu, N = arm.nx, arm.nu, s.horizon
    u_max = (1.0 - s.torque_margin) * np.asarray(arm.torque_limit, dtype=float)
    if not np.all(u_max > 0):
        raise ValueError(f"MPC torque bounds must be > 0, got {u_max}")
    env = envelope_rows(arm, s, u_max)
    blocks = s.block_lengths
    nb, nz = len(blocks), nu * len(blocks)
    nv, npar = nz + env.ns, nx + N * arm.ny + nu + arm.ny
    block_of_tick = np.repeat(np.arange(nb), blocks)
    blocking = np.zeros((N * nu, nz))
    for k, b in enumerate(block_of_tick):
        blocking[k * nu:(k + 1) * nu, b * nu:(b + 1) * nu] = np.diag(u_max)
    terminal_weight = _terminal_weight(arm, s, u_max)
    H, F, f0, Jz, Jp, g0 = _extract(arm, s, u_max, env, blocking, terminal_weight)
    try:
        chol = scipy.linalg.cho_factor(H)
    except np.linalg.LinAlgError:
        raise ValueError(
            "the QP Hessian is not positive definite; raise effort_weight or rate_weight"
        ) from None
    # the soft envelope: slacks, rows, bounds
    Amat, G, l0, u0 = _constraints(env, Jz.reshape(-1, nz), Jp.reshape(-1, npar), g0, blocks,
                                   arm.Ts, nz)
    P = scipy.linalg.block_diag(H, s.envelope_quadratic * np.eye(env.ns))
    F_all = np.vstack([F, np.zeros((env.ns, npar))])
    f0_all = np.concatenate([f0, np.full(env.ns, s.envelope_penalty)])
    # the unconstrained minimiser over ẑ with s = 0 (screening, LQ fallback)
    Z = np.zeros((nv, npar + 1))
    Z[:nz] = -scipy.linalg.cho_solve(chol, np.column_stack([F, f0]))
    shift, shift_dual = _shift_matrices(blocks, nu, env, Amat.shape[0])
    cols = np.flatnonzero(np.any(G != 0, axis=0))
    return CondensedQP(
        P=P, F=F_all, f0=f0_all, A=Amat, G=G, l0=l0, u0=u0, param_bounds=bool(cols.size),
        bound_columns=cols, u_max=u_max, scale=np.tile(u_max, nb), blocking=blocking,
        block_of_tick=block_of_tick, shift=shift, shift_dual=shift_dual, minimiser=Z,
        gain=u_max[:, None] * Z[:nu, :-1], gain0=u_max * Z[:nu, -1],
        terminal_weight=terminal_weight, envelope=env, slack_names=env.names, N=N, nx=nx,
        nu=nu, ny=arm.ny, nz=nz,
    )


def _terminal_weight(arm: LinearArm, s: MPCSettings, u_max: np.ndarray) -> np.ndarray | None:
    """P∞ − Q_x of the DARE for the last point's tracking weight (``terminal="dare"``), or None.

    With Q_x = Cᵀ q w_N C and R = effort_weight·diag(1/u_max²), P∞ solves the discrete algebraic
    Riccati equation of (A, B, Q_x, R); the terminal cost adds the tail of the infinite horizon.
    """
    if s.terminal != "dare":
        return None
    if s.effort_weight <= 0:
        raise ValueError("terminal='dare' needs effort_weight > 0 (R positive definite)")
    C = np.asarray(arm.C, dtype=float)
    w_last = 1.0 if s.point_weights is None else float(s.point_weights[-1])
    Qx = C.T @ (s.tracking_weight / s.position_scale**2 * w_last * np.eye(arm.ny)) @ C
    R = s.effort_weight * np.diag(1.0 / u_max**2)
    P_inf = scipy.linalg.solve_discrete_are(np.asarray(arm.A, dtype=float),
                                            np.asarray(arm.B, dtype=float), Qx, R)
    return 0.5 * ((P_inf - Qx) + (P_inf - Qx).T)


def _extract(arm: LinearArm, s: MPCSettings, u_max: np.ndarray, env, blocking: np.ndarray,
             terminal_weight: np.ndarray | None) -> tuple[np.ndarray, ...]:
    """The cost and envelope rows in CasADi, and their derivatives at (z, p) = 0.

    Cost over the horizon, with x_{k+1} = A x_k + B u_k, y_k − y0 = C x_k + d and the blocked
    inputs u = blocking·z::

        Σ_k  uᵀR u + Δuᵀ R_Δ Δu + q w_k ‖y_k − r_k‖²   (+ the DARE terminal cost)

    Returns H, F = ∂∇J/∂p, f0 = ∇J(0, 0), ∂g/∂z, ∂g/∂p, g(0, 0) (g: the envelope rows).
    """
    import casadi as ca  # only where the QP is formulated, not where it is cached
    A, B, C = (ca.DM(np.asarray(m, dtype=float)) for m in (arm.A, arm.B, arm.C))
    y0 = ca.DM(np.asarray(arm.y0, dtype=float))
    nx, nu, ny, N, nz = arm.nx, arm.nu, arm.ny, s.horizon, blocking.shape[1]
    nq, npar = nx // 2, nx + N * ny + nu + ny
    w = np.ones(N) if s.point_weights is None else np.asarray(s.point_weights, dtype=float)
    q_scale = s.tracking_weight / s.position_scale**2
    R = ca.DM(s.effort_weight * np.diag(1.0 / u_max**2))
    R_d = ca.DM(s.rate_weight * np.diag(1.0 / u_max**2))
    z, p = ca.SX.sym("z", nz), ca.SX.sym("p", npar)
    x, r = p[:nx], ca.reshape(p[nx:nx + N * ny], ny, N)  # column k = r_{k+1}
    u_prev, d = p[nx + N * ny:nx + N * ny + nu], p[nx + N * ny + nu:]
    u_seq = ca.mtimes(ca.DM(blocking), z)
    Dq, Dv, Dy = ca.DM(env.Dq), ca.DM(env.Dv), ca.DM(env.Dy)
    block_ends = set(np.cumsum(s.block_lengths).tolist())  # k+1 of each block's last state
    cost, env_rows = 0, []
    for k in range(N):
        u = u_seq[k * nu:(k + 1) * nu]
        cost += ca.bilin(R, u, u) + ca.bilin(R_d, u - u_prev, u - u_prev)
        x = ca.mtimes(A, x) + ca.mtimes(B, u)
        y_rel = ca.mtimes(C, x) + d  # y − y0
        e = y_rel + y0 - r[:, k]
        cost += q_scale * w[k] * ca.dot(e, e)
        if env.m and (k + 1) in block_ends:
            env_rows.append(ca.mtimes(Dq, x[:nq]) + ca.mtimes(Dv, x[nq:]) + ca.mtimes(Dy, y_rel))
        u_prev = u
    if terminal_weight is not None:
        Cq_pinv = ca.DM(np.linalg.pinv(np.asarray(arm.C, dtype=float)[:, :nq]))
        x_ss = ca.vertcat(ca.mtimes(Cq_pinv, r[:, N - 1] - y0 - d), ca.DM.zeros(nq))
        cost += ca.bilin(ca.DM(terminal_weight), x - x_ss, x - x_ss)
    g = ca.vertcat(*env_rows) if env_rows else ca.SX.zeros(0, 1)
    hess, grad = ca.hessian(cost, z)
    outputs = [hess, ca.jacobian(grad, p), grad, ca.jacobian(g, z), ca.jacobian(g, p), g]
    values = ca.Function("extract", [z, p], outputs)(np.zeros(nz), np.zeros(npar))
    H, F, f0, Jz, Jp, g0 = (np.array(v, dtype=float) for v in values)
    H = 0.5 * (H + H.T)
    if not (np.all(np.isfinite(H)) and np.all(np.isfinite(F)) and np.all(np.isfinite(f0))):
        raise ValueError("the QP data are not finite; check the weights and the arm")
    return H, F, f0.ravel(), Jz, Jp, g0.ravel()


def _shift_matrices(blocks, nu: int, env, m: int) -> tuple[np.ndarray, np.ndarray]:
    """The one-tick shift of a blocked plan (primal, and dual over all m rows), projected back
    onto the blocks: S_b[b(k), b(k+1)] = 1/len(b(k)) summed over the ticks k of each block."""
    nb, N = len(blocks), int(np.sum(blocks))
    block_of_tick = np.repeat(np.arange(nb), blocks)
    S_b = np.zeros((nb, nb))
    for k in range(N):
        S_b[block_of_tick[k], block_of_tick[min(k + 1, N - 1)]] += 1.0
    S_b /= np.asarray(blocks, dtype=float)[:, None]
    shift = scipy.linalg.block_diag(np.kron(S_b, np.eye(nu)), np.eye(env.ns))
    nv = shift.shape[0]
    shift_dual = np.zeros((m, m))
    shift_dual[:nv, :nv] = shift
    if env.m:
        shift_dual[nv:, nv:] = np.kron(S_b, np.eye(2 * env.m))
    return shift, shift_dual


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
