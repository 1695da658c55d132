"""Level 2 of the screening cascade: the torque-box QP, solved exactly by active-set methods.

The MPC's QP (:mod:`rhmpc.control.qp`) over ``v = [ẑ; s]`` has torque boxes ``−1 ≤ ẑ ≤ 1``,
slack bounds ``s ≥ 0`` and the envelope rows. With the slacks fixed at 0 and the envelope rows
left out it is the *box QP*::

    min_z ½ zᵀ H z + qᵀ z   s.t.   −1 ≤ z ≤ 1          (H = P_zz ≻ 0, z ∈ ℝ^nz)

Range-space (Schur-complement) step
    With ``W = H⁻¹`` (computed once, at build time) and the unconstrained minimiser
    ``ẑ* = −W q``, the minimiser with the bounds of an active set 𝒜 held as equalities
    ``z_𝒜 = b_𝒜`` (``b_i = ±1``) and its multipliers are::

        W_𝒜𝒜 μ_𝒜 = ẑ*_𝒜 − b_𝒜,     z = ẑ* − W_{:,𝒜} μ_𝒜,     H z + q + E_𝒜 μ_𝒜 = 0

    (Nocedal & Wright, *Numerical Optimization*, 2nd ed., §16.2, range-space / Schur-complement
    method). ``W_𝒜𝒜`` is a principal submatrix of an SPD matrix, so it is SPD and factorised by
    Cholesky; it has ``|𝒜|`` rows. An active upper bound needs ``μ_i ≥ 0``, an active lower
    bound ``μ_i ≤ 0`` (OSQP's sign convention for ``z ≤ 1``).

Phase 1: primal-dual active set (PDAS)
    Hintermüller, Ito & Kunisch, *SIAM J. Optim.* 13(3), 865–888, 2002 (a semismooth Newton
    method on the KKT conditions): the next set keeps the active bounds whose multiplier has
    the right sign and adds every free variable that violates its bound::

        𝒜⁺ = {i ∈ 𝒜 : b_i μ_i ≥ −ε_d} ∪ {i ∉ 𝒜 : |z_i| > 1 + ε_p}

    It stops when 𝒜⁺ = 𝒜: then every KKT condition of the box QP holds (within the
    tolerances). It starts from the bounds the unconstrained minimiser ẑ* violates (stateless:
    the tick's decision depends on its QP alone). PDAS can cycle when H is not an M-matrix
    (Kunisch & Rendl, *ESAIM: M2AN* 37(6), 2003) — this H couples neighbouring blocks
    strongly — so it gets ``pdas_iter`` solves.

Phase 2: dual active set (Goldfarb & Idnani, *Math. Program.* 27, 1–33, 1983)
    If PDAS has not converged, the dual method starts again from ẑ* (𝒜 = ∅, dual feasible)
    and adds the most violated bound p (``σ_p z_p ≤ 1``), raising its multiplier λ_p along::

        r = (Nᵀ W N)⁻¹ Nᵀ W n_p,   s = W n_p − W N r,   z ← z − t s,   λ_𝒜 ← λ_𝒜 − t r,
        λ_p ← λ_p + t,   t = min(full step to z_p = σ_p, first λ_j reaching 0)

    (``N`` the active bounds' normals σ_i e_i; a partial step drops bound j and continues
    with p). The dual objective rises at every step, so no active set repeats: it terminates
    in finitely many steps in exact arithmetic. Each step is one Cholesky of ``W_𝒜𝒜``. Bounds
    whose violations tie within rounding enter in the order of their index, so that the path,
    and the number of solves, is the same on every processor: violations within ε_p of the
    largest are a tie, broken by the lowest index.
    Solves of both phases count towards ``max_iter``; past it the tick takes the fallback.

Certificate
    A result is accepted only if the stationarity residual, computed from ``H`` and ``q`` (not
    from ``W``), is small: ``‖H z + q + E_𝒜 μ‖∞ ≤ ε_kkt (1 + ‖q‖∞)``. Every other KKT condition
    is checked by the stopping rule, so an accepted z is the box QP's unique minimiser to
    rounding.

Why that is the full QP's optimum (the caller checks the envelope): if the box minimiser z
satisfies every envelope row with zero slack, then ``v = [z; 0]`` with multipliers μ on the
torque rows, ``−ρ₁`` on the slack bounds (active lower bounds, the stationarity in s at s = 0:
ρ₂·0 + ρ₁ + y_s = 0) and **zero on every envelope row** satisfies the full QP's KKT conditions:
the envelope rows then add nothing to the stationarity in z, which is the box QP's. P ≻ 0 makes
that point the unique optimum. (Level 1, ``μ = 0``, is the special case 𝒜 = ∅.)

The generated C (``rhmpc export``) runs the same algorithm in the same order on the same ``W``
and ``H`` (:mod:`rhmpc.control.export`), so the two take the same decisions tick for tick.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg.lapack import dpotrf as _potrf
from scipy.linalg.lapack import dpotrs as _potrs


def _peak(v: np.ndarray) -> float:
    """max(v) by argmax (a quarter of ``max()``'s cost on a few dozen entries; NaN wins)."""
    return float(v[v.argmax()])


def _most_violated(viol: np.ndarray, tie: float) -> int:
    """The index of the largest violation, the lowest among those within ``tie`` of it (the
    primal tolerance: violations the solver cannot tell apart, so that the rounding of one
    processor or BLAS against another's never decides which bound enters next)."""
    top = viol[viol.argmax()]
    return int((viol >= top - tie).argmax())


@dataclass(frozen=True)
class BoxQPSettings:
    """Settings of :class:`BoxQP`.

    Attributes
    ----------
    max_iter : int
        Cap on the Cholesky solves per tick, both phases together [-]; past it the call
        returns without an answer (``capped``).
    pdas_iter : int
        Solves of phase 1 (PDAS) before phase 2 (the dual active set) takes over [-].
    primal_tol : float
        ε_p: a free variable counts as violating its bound when ``|z_i| > 1 + ε_p``
        [normalised torque, 1 = u_max]. The applied torque is clipped to ±u_max anyway.
    dual_tol : float
        ε_d: an active bound is kept while ``b_i μ_i ≥ −ε_d (1 + ‖q‖∞)`` [relative to the
        cost's gradient scale, -].
    kkt_tol : float
        ε_kkt: acceptance bound on the stationarity residual relative to ``1 + ‖q‖∞`` [-].
    """

    max_iter: int = 16
    pdas_iter: int = 3
    primal_tol: float = 1e-9
    dual_tol: float = 1e-9
    kkt_tol: float = 1e-9

    def __post_init__(self) -> None:
        for name in ("max_iter", "pdas_iter"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        for name in ("primal_tol", "dual_tol", "kkt_tol"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, got {v!r}")


class BoxQP:
    """Exact solver of ``min ½ zᵀHz + qᵀz, −1 ≤ z ≤ 1`` (see the module docstring).

    Parameters
    ----------
    H : (n, n) symmetric positive definite Hessian [-]
    settings : BoxQPSettings

    Attributes
    ----------
    W : (n, n) H⁻¹, symmetrised [-] (exported as is to C)
    z : (n,) the last solution [-]
    mu : (n,) its bound multipliers (0 on free variables; ≥ 0 at +1, ≤ 0 at −1) [-]
    iterations : int
        Active-set solves of the last call (0 if it returned before the first).
    capped : bool
        Whether the last call stopped at ``max_iter`` solves without an answer.
    active : (n,) int8, sign of each active bound of the last call (0 = free)
    """

    def __init__(self, H: np.ndarray, settings: BoxQPSettings | None = None) -> None:
        H = np.asarray(H, dtype=float)
        if H.ndim != 2 or H.shape[0] != H.shape[1]:
            raise ValueError(f"H must be square, got shape {H.shape}")
        self.settings = settings if settings is not None else BoxQPSettings()
        self.H = np.ascontiguousarray(0.5 * (H + H.T))
        W = np.linalg.inv(np.linalg.cholesky(self.H))  # L⁻¹; W = L⁻ᵀ L⁻¹
        W = W.T @ W
        self.W = np.ascontiguousarray(0.5 * (W + W.T))
        self._negW = -self.W
        n = self.H.shape[0]
        self.n = n
        self.z = np.zeros(n)
        self.mu = np.zeros(n)
        self.iterations = 0
        self.capped = False
        self.active = np.zeros(n, dtype=np.int8)
        self._r = np.empty(n)
        self._viol = np.empty(n)
        self._act = np.zeros(n, dtype=np.intp)
        self._sig = np.zeros(n)
        self._lam = np.zeros(n)

    def unconstrained(self, q: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """ẑ* = −W q, the unconstrained minimiser (level 1's candidate)."""
        return np.dot(self._negW, q, out=out)

    def solve(self, q: np.ndarray, z_star: np.ndarray) -> bool:
        """Solve the box QP for ``q`` (n,), given ``z_star`` = −W q; True if the KKT conditions
        hold (then :attr:`z`, :attr:`mu` are the minimiser and its multipliers).

        Returns False without a step when ẑ* violates no bound (the box QP's minimiser is ẑ*
        itself: if level 1 rejected it, an envelope row is the reason), and False when the cap
        is reached or the certificate fails.
        """
        st = self.settings
        self.iterations = 0
        self.capped = False
        if not _peak(np.abs(z_star)) > 1.0:
            return False
        scale = 1.0 + _peak(np.abs(q))
        act = self._pdas(z_star, scale)
        if act is None:
            act = self._dual_active_set(z_star, scale)
            if act is None:
                return False
        mu = self.mu
        self.active[:] = 0
        self.active[act] = self.z[act]  # exactly ±1
        r = np.dot(self.H, self.z, out=self._r)
        r += q
        r += mu
        return bool(_peak(np.abs(r, out=r)) <= st.kkt_tol * scale)

    def _pdas(self, z_star: np.ndarray, scale: float) -> np.ndarray | None:
        """Phase 1, primal-dual active set: the final active indices (z, mu set), or None
        after ``pdas_iter`` solves without convergence."""
        st = self.settings
        W = self.W
        dual_tol = st.dual_tol * scale
        upper = 1.0 + st.primal_tol
        act = (np.abs(z_star) > 1.0).nonzero()[0]
        b = np.copysign(1.0, z_star[act])
        sign = self.active
        for it in range(1, min(st.pdas_iter, st.max_iter) + 1):
            self.iterations = it
            W_a = W[act]  # rows 𝒜 = columns 𝒜 (W symmetric)
            L, info = _potrf(W_a[:, act], lower=1)
            if info != 0:
                return None
            mu, info = _potrs(L, z_star[act] - b, lower=1)
            if info != 0:
                return None
            z = z_star - mu @ W_a
            z[act] = b  # exactly ±1: never counted as past a bound below
            bmu = b * mu
            join = (np.abs(z) > upper).nonzero()[0]  # free variables past a bound join
            if join.size == 0 and bmu[bmu.argmin()] >= -dual_tol:
                self.z[:] = z
                self.mu[:] = 0.0
                self.mu[act] = mu
                return act
            sign[:] = 0
            keep = bmu >= -dual_tol  # active bounds with a wrong-sign multiplier leave
            sign[act[keep]] = b[keep]
            sign[join] = np.where(z[join] > 0.0, 1, -1)
            act = sign.nonzero()[0]
            if act.size == 0:  # every bound left: ẑ*, which violates them
                return None
            b = sign[act].astype(float)
        return None

    def _dual_active_set(self, z_star: np.ndarray, scale: float) -> np.ndarray | None:
        """Phase 2, Goldfarb–Idnani dual active set from ẑ* (𝒜 = ∅): the final active indices
        (z, mu set), or None at the cap. Solves so far count towards ``max_iter``."""
        st = self.settings
        W = self.W
        z = self.z
        z[:] = z_star
        viol = np.abs(z, out=self._viol)
        viol -= 1.0
        p = _most_violated(viol, st.primal_tol)
        # the active bounds in the order they were added: index, sign σ_i (+1: z_i ≤ 1,
        # −1: −z_i ≤ 1) and multiplier λ_i ≥ 0, in the first k entries of fixed buffers
        act_b, sig_b, lam_b = self._act, self._sig, self._lam
        k = 0
        it = self.iterations
        while viol[p] > st.primal_tol:  # add bound p: raise λ_p from 0 until z_p = σ_p
            sp = 1.0 if z[p] > 0.0 else -1.0
            lam_p = 0.0
            while True:
                it += 1
                if it > st.max_iter:
                    self.capped = True
                    return None
                self.iterations = it
                j = -1
                if k:
                    act, sig, lam = act_b[:k], sig_b[:k], lam_b[:k]
                    W_a = W[act]  # rows 𝒜 = columns 𝒜 (W symmetric)
                    L, info = _potrf(W_a[:, act], lower=1)
                    if info != 0:
                        return None
                    y, info = _potrs(L, W_a[:, p] * sp, lower=1)
                    if info != 0:
                        return None
                    step = sp * W[p] - y @ W_a  # s = W n_p − W N r
                    r = sig * y  # dual step direction of the active multipliers
                    t = (sp * z[p] - 1.0) / (sp * step[p])  # full step: z_p reaches σ_p
                    if _peak(r) > 0.0:  # partial step: an active λ reaches 0 first
                        for a in (r > 0.0).nonzero()[0].tolist():
                            ratio = lam[a] / r[a]
                            if ratio < t:
                                t, j = ratio, a
                    z -= t * step
                    lam -= t * r
                    z[act] = sig
                else:
                    step = sp * W[p]
                    t = (sp * z[p] - 1.0) / (sp * step[p])
                    z -= t * step
                lam_p += t
                if j < 0:
                    break
                # bound j leaves; p is still the target
                act_b[j:k - 1] = act_b[j + 1:k]
                sig_b[j:k - 1] = sig_b[j + 1:k]
                lam_b[j:k - 1] = lam_b[j + 1:k]
                k -= 1
            act_b[k], sig_b[k], lam_b[k] = p, sp, lam_p
            k += 1
            z[p] = sp
            np.abs(z, out=viol)
            viol -= 1.0
            p = _most_violated(viol, st.primal_tol)
        if k and _peak(-lam_b[:k]) > st.dual_tol * scale:
            return None
        self.mu[:] = 0.0
        self.mu[act_b[:k]] = sig_b[:k] * lam_b[:k]
        return act_b[:k].copy()
