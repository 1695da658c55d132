"""The MPC's settings: a frozen dataclass with the units of every field.

Settings are validated when they are constructed (what can be checked without a robot) and again
when a controller is built (what depends on the robot, e.g. the torque limits left after the
cancellation margin).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Default move-blocking of the MPC inputs [ticks]: short blocks first, longer ones towards the end
#: of the 50-tick horizon; 10 blocks (30 QP variables for 3 joints), sum 50.
DEFAULT_BLOCKS: tuple[int, ...] = (2, 2, 3, 3, 4, 5, 6, 7, 8, 10)

CARTESIAN: tuple[str, ...] = ("none", "halfspace", "box")
TERMINALS: tuple[str, ...] = ("none", "dare")


def _finite(name: str, value: float, *, positive: bool = False, nonneg: bool = False) -> None:
    if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    if positive and not value > 0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    if nonneg and not value >= 0:
        raise ValueError(f"{name} must be >= 0, got {value!r}")


def _integer(name: str, value: int, minimum: int) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")


@dataclass(frozen=True)
class MPCSettings:
    """Settings of :class:`rhmpc.control.mpc.RecedingHorizonMPC`.

    The QP solved every tick (``x`` = [q − q0; q̇], ``u`` = τ_mpc, ``y`` = C x + y0 + d)::

        min  Σ_{k=1..N} ‖y_k − r_k‖²_{Q_k} + Σ_{k=0..N−1} ‖u_k‖²_R + ‖u_k − u_{k−1}‖²_{R_Δ}
             (+ ‖x_N − x_ss(r_N)‖²_{P_∞ − CᵀQ_N C}  if terminal == "dare")
             + Σ_groups ρ₁ s_g + ½ ρ₂ s_g²
        s.t. x_{k+1} = A x_k + B u_k,  |u_k| ≤ u_max = (1 − torque_margin) τ_max  (hard),
             u_k constant over each move block,
             q_lo − s ≤ q_k ≤ q_hi + s,  |q̇_k| ≤ q̇_max + s,  Cartesian set (+ s)  (soft, s ≥ 0)

    ``d = p(q̂) − (C x̂ + y0)`` is the output offset from forward kinematics
    (:mod:`rhmpc.control.export.dynamics`); the envelope rows and their slacks are described in
    :mod:`rhmpc.control.envelope`.

    with ``Q_k = tracking_weight · w_k / position_scale² · I``, ``R = effort_weight ·
    diag(u_max)⁻²``, ``R_Δ = rate_weight · diag(u_max)⁻²`` (all costs dimensionless).

    Attributes
    ----------
    horizon : int
        N, number of predicted ticks and of reference points [ticks].
    blocks : tuple[int, ...] | None
        Move-blocking: lengths of the intervals over which the input is held [ticks]; they must
        sum to ``horizon``. ``None`` = no blocking (one free input per tick).
    position_scale : float
        Position error that costs 1 (per point, before weights) [m].
    tracking_weight : float
        Weight of the tracking term [-].
    point_weights : tuple[float, ...] | None
        Per-point multipliers w_1..w_N of Q_k (e.g. prediction confidence) [-]; ``None`` = all 1.
    effort_weight : float
        Weight of ‖u/u_max‖² per tick [-].
    rate_weight : float
        Weight of ‖(u_k − u_{k−1})/u_max‖² per tick; u_{−1} is the previous applied τ_mpc [-].
    terminal : str
        ``"none"`` or ``"dare"``: terminal weight that completes the infinite-horizon LQ cost-to-go
        P_∞ (discrete algebraic Riccati equation for CᵀQ_N C, R), about the steady state
        x_ss = [C_q⁺ (r_N − y0); 0].
    torque_margin : float
        Fraction of each joint's torque limit reserved for the nonlinearity cancellation [-].
    offset_correction : bool
        Correct the linearised output by the offset ``d`` computed by forward kinematics at the
        estimated joint state every tick (offset-free MPC). Needs the arm's robot.
    joint_envelope : bool
        Enforce the joint position and velocity limits, and the robot's coupled joint limits
        (:attr:`rhmpc.robots.Robot.coupling`, e.g. the PHANToM's parallelogram), soft with an exact
        L1 penalty, at every move block's end, certified in between
        (:mod:`rhmpc.control.envelope`).
    joint_lower, joint_upper : tuple[float, ...] | None
        Absolute joint position limits [rad]; ``None`` = the robot model's (URDF) limits.
    velocity_limit : tuple[float, ...] | None
        Joint speed limits [rad/s]; ``None`` = the robot model's (URDF) limits.
    cartesian : str
        Optional Cartesian envelope of the end-effector position: ``"none"``, ``"halfspace"``
        (the tool may not go more than ``cartesian_depth`` past the plane through
        ``cartesian_point`` with normal ``cartesian_normal``, the normal pointing into the
        forbidden side) or ``"box"`` (``|y − y0 − cartesian_point| ≤ cartesian_half_width`` per
        axis).
    cartesian_point : tuple[float, float, float]
        A point of the plane, or the box centre, relative to the end-effector's home position y0
        (where the loop puts the mean POI when ``poi_offset`` is 0) [m].
    cartesian_normal : tuple[float, float, float]
        Plane normal, pointing into the forbidden side (normalised when used) [-].
    cartesian_depth : float
        How far past the plane the tool may go [m] (negative: must stay that far in front).
    cartesian_half_width : tuple[float, float, float]
        Half-widths of the box [m].
    envelope_penalty : float
        ρ₁, exact L1 penalty per slack unit [-]; the envelope is exact when ρ₁ exceeds the
        multipliers of the hard constraints.
    envelope_quadratic : float
        ρ₂, quadratic slack weight [-]; it keeps the Hessian positive definite in the slacks.
    max_iter : int
        OSQP's ADMM iterations per tick [-] on the ticks the screening cascade hands it (an
        envelope row binds): a bound on the tick's work, each iteration a solve with the
        factorised KKT matrix (``rhmpc bench --controller c`` times the exported tick). A solve
        that reaches it is not used: the tick takes the fallback, and the next tick's solve
        starts from its iterate, shifted one tick (its QP is nearly the same), so that a solve
        that needs more iterations finishes over a few ticks. A cap in iterations rather than
        time keeps runs reproducible.
    osqp_rho : float
        ρ, OSQP's ADMM step size [-] (Stellato et al., "OSQP: an operator splitting solver for
        quadratic programs", Math. Prog. Comp. 12, 2020), fixed: the KKT matrix is factorised
        once.
    osqp_eps_abs : float
        OSQP's absolute termination tolerance on the primal and dual residuals, on the QP
        scaled by u_max (inputs of magnitude ≤ 1) [-]; the relative one is 0.
    box_max_iter : int or None
        Cap on level 2's active-set solves (Cholesky factorisations of at most nz × nz) per
        tick [-]; past it the tick takes the fallback (:mod:`rhmpc.control.mpc`). None
        (default): its PDAS solves plus nz, those of a dual phase in which every torque bound
        enters once and none leaves (Goldfarb & Idnani 1983).
    backoff_max_ticks : int
        Longest rest of levels 2 and 3 after consecutive failed ticks [ticks]: after k of
        them the next ``min(2ᵏ − 1, backoff_max_ticks)`` ticks take the fallback unless level
        1 settles them (:mod:`rhmpc.control.mpc`, "Back-off"). 255 keeps the ticks that try
        the solver to 0.4 % of a stream it cannot settle (2⁸ = 256), below the 1 % that sets
        a tick time's p99; 0 tries every tick.
    plan_fallback_ticks : int
        After a failed solve, the previous plan (shifted) is used for at most this many ticks
        since it was computed; later failures use the clipped unconstrained LQ solution [ticks].
    """

    horizon: int = 50
    blocks: tuple[int, ...] | None = DEFAULT_BLOCKS
    position_scale: float = 1e-3
    tracking_weight: float = 1.0
    point_weights: tuple[float, ...] | None = None
    effort_weight: float = 1e-4
    rate_weight: float = 0.1
    terminal: str = "none"
    torque_margin: float = 0.25
    offset_correction: bool = True
    joint_envelope: bool = True
    joint_lower: tuple[float, ...] | None = None
    joint_upper: tuple[float, ...] | None = None
    velocity_limit: tuple[float, ...] | None = None
    cartesian: str = "none"
    cartesian_point: tuple[float, float, float] = (0.0, 0.0, 0.0)
    cartesian_normal: tuple[float, float, float] = (0.0, 0.0, -1.0)
    cartesian_depth: float = 2e-3
    cartesian_half_width: tuple[float, float, float] = (5e-3, 5e-3, 5e-3)
    envelope_penalty: float = 1e3
    envelope_quadratic: float = 1e2
    max_iter: int = 10
    osqp_rho: float = 3.0
    osqp_eps_abs: float = 1e-3
    box_max_iter: int | None = None
    backoff_max_ticks: int = 255
    plan_fallback_ticks: int = 10

    def __post_init__(self) -> None:
        for name in ("blocks", "point_weights", "joint_lower", "joint_upper", "velocity_limit",
                     "cartesian_point", "cartesian_normal", "cartesian_half_width"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, tuple(value))
        self._check_horizon()
        self._check_weights()
        self._check_envelope()
        self._check_solver()
        for name in ("offset_correction", "joint_envelope"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}")

    def _check_horizon(self) -> None:
        _integer("horizon", self.horizon, 1)
        if self.blocks is not None:
            if len(self.blocks) == 0:
                raise ValueError("blocks must not be empty (use None for no blocking)")
            for b in self.blocks:
                _integer("each move block", b, 1)
            if sum(self.blocks) != self.horizon:
                raise ValueError(
                    f"move blocks must sum to the horizon {self.horizon}, got {sum(self.blocks)}"
                )

    def _check_weights(self) -> None:
        _finite("position_scale", self.position_scale, positive=True)
        _finite("tracking_weight", self.tracking_weight, positive=True)
        if self.point_weights is not None:
            if len(self.point_weights) != self.horizon:
                raise ValueError(
                    f"point_weights must have {self.horizon} entries, got {len(self.point_weights)}"
                )
            for w in self.point_weights:
                _finite("each point weight", w, nonneg=True)
            if not any(w > 0 for w in self.point_weights):
                raise ValueError("at least one point weight must be > 0")
        _finite("effort_weight", self.effort_weight, nonneg=True)
        _finite("rate_weight", self.rate_weight, nonneg=True)
        if self.terminal not in TERMINALS:
            raise ValueError(f"terminal must be one of {TERMINALS}, got {self.terminal!r}")
        _finite("torque_margin", self.torque_margin, nonneg=True)
        if self.torque_margin >= 1:
            raise ValueError(f"torque_margin must be < 1 (a fraction), got {self.torque_margin}")

    def _check_envelope(self) -> None:
        if (self.joint_lower is None) != (self.joint_upper is None):
            raise ValueError("give both joint_lower and joint_upper, or neither")
        if self.joint_lower is not None:
            if len(self.joint_lower) != len(self.joint_upper):
                raise ValueError("joint_lower and joint_upper must have the same length")
            for lo, hi in zip(self.joint_lower, self.joint_upper, strict=True):
                _finite("joint bound", lo)
                _finite("joint bound", hi)
                if not lo < hi:
                    raise ValueError(f"joint_lower must be < joint_upper, got {lo} >= {hi}")
        if self.velocity_limit is not None:
            for v in self.velocity_limit:
                _finite("each velocity limit", v, positive=True)
        if self.cartesian not in CARTESIAN:
            raise ValueError(f"cartesian must be one of {CARTESIAN}, got {self.cartesian!r}")
        for name in ("cartesian_point", "cartesian_normal", "cartesian_half_width"):
            value = getattr(self, name)
            if len(value) != 3:
                raise ValueError(f"{name} must have 3 entries [m], got {value!r}")
            for v in value:
                _finite(name, v)
        if not any(v != 0 for v in self.cartesian_normal):
            raise ValueError("cartesian_normal must not be zero")
        for v in self.cartesian_half_width:
            _finite("cartesian_half_width", v, positive=True)
        _finite("cartesian_depth", self.cartesian_depth)
        _finite("envelope_penalty", self.envelope_penalty, positive=True)
        _finite("envelope_quadratic", self.envelope_quadratic, positive=True)

    def _check_solver(self) -> None:
        _integer("max_iter", self.max_iter, 1)
        _finite("osqp_rho", self.osqp_rho, positive=True)
        _finite("osqp_eps_abs", self.osqp_eps_abs, positive=True)
        _integer("plan_fallback_ticks", self.plan_fallback_ticks, 0)
        if self.box_max_iter is not None:
            _integer("box_max_iter", self.box_max_iter, 1)
        _integer("backoff_max_ticks", self.backoff_max_ticks, 0)
        if self.backoff_max_ticks > 2**30:
            raise ValueError(f"backoff_max_ticks must be <= 2**30, got {self.backoff_max_ticks}")

    @property
    def block_lengths(self) -> tuple[int, ...]:
        """Move-block lengths [ticks]; all ones when blocking is off."""
        return self.blocks if self.blocks is not None else (1,) * self.horizon
