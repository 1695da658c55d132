"""Spatio-temporal RLS: one linear forecaster of the point of interest (POI) from the recent
motion of every tracked point, adapted online from the first sample.

The stereo-video trackers of the beating heart follow several points of one surface at once
(four in Zhang et al. 2022, IEEE SPL 29:787), and the points move together: the other points'
past tells the POI's future. This predictor is the linear model of that coupling, a vector
autoregression with the other points as exogenous inputs (VARX, Lütkepohl 2005, *New
Introduction to Multiple Time Series Analysis*, ch. 10), fitted by RLS with the generalized
predictor's direct blocks (Tuna et al. 2013, §VI; :mod:`rhmpc.predictors.rls_generalized`).

Model.  With r_n = [z_n; o_n^1; …; o_n^{P−1}] ∈ ℝ^{Pd} the stacked samples of the POI z and the
P − 1 other points at instant n, the increment form (translation-equivariant: the forecast
moves with the whole scene, and no intercept is needed)

    x_n = [r_{n−1} − r_n; …; r_{n−N+1} − r_n]        ((N − 1)·P·d regressors),
    [r̂_{n+1} − r_n; …; r̂_{n+M} − r_n] = V x_n         (M blocks of P·d outputs),

is learnt from the M-step-delayed problem, whose every quantity has been observed (eq. 10):
V x_{n−M} ≈ [r_{n−M+1} − r_{n−M}; …; r_n − r_{n−M}]. V₀ = 0 is the hold forecast. The POI's
forecast is the first d rows of each block; beyond M leads the blocks are chained (the M
forecasts of every point pushed as if observed), as in the generalized predictor.

Gaps.  A missing sample of any point is filled by the model's own one-step forecast of it
(its newest sample while the model is not ready); windows with a filled value teach nothing;
when a whole row returns, the fills of the gap are repaired as in
:class:`rhmpc.predictors.delay_line.TappedDelayLine`, and measured values are never altered.

With independent axes (``correlated=False``, the default) each axis is one such problem on
that axis of every point. Cost per update: one Sherman–Morrison step per problem, ≈ 2n² + 2nq
multiply-adds, n = (N − 1)·P and q = M·P per axis (N = 24, P = 4, M = 4: 3 × 19.9 k), or
n = (N − 1)·P·d and q = M·P·d correlated (≈ 0.18 M).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rhmpc.predictors.base import Predictor, PredictorSettings
from rhmpc.predictors.delay_line import TappedDelayLine
from rhmpc.predictors.rls import RecursiveLeastSquares

__all__ = ["PointsDelayLine", "SpatioTemporalRLS", "SpatioTemporalSettings"]


@dataclass(frozen=True)
class SpatioTemporalSettings(PredictorSettings):
    """Spatio-temporal RLS settings.

    Attributes
    ----------
    order : int
        N, samples of every point in the embedding [-]. 24 = 0.96 s at the 25 frames/s of
        stereo video: one cardiac cycle down to 62 beats/min, the span a linear predictor of a
        periodic motion needs to see one period of it.
    leads : int
        M, leads with their own weight block [-]; 4 (160 ms at 25 frames/s: the closed
        loop's lead of 2 samples and the literature's 4-step horizon).
    correlated : bool
        True: one problem, every axis of every point read for every output ((N − 1)·P·d
        weights per output); False: one problem per axis, that axis of every point
        (Tuna et al. 2013 §VII-A's independent axes, (N − 1)·P weights per output). The
        default is False: the RLS's misadjustment, the excess mean squared error of its
        noisy weights, is n(1 − λ)/(1 + λ) for n weights (Haykin 2001, §13.5): 4.6 % for the
        92 weights of the default, 14 % for the 276 of the correlated problem.
    forgetting_factor : float
        λ ∈ (0, 1] [-], per sample. 0.999, the RLS family's value: a memory of 1000 samples
        (40 s at 25 Hz).
    delta : float
        Prior weight δ [m²] of V₀ = 0 (the hold), P₀ = I/δ in data units (δ/unit²). 1e-8 m²:
        (0.1 mm)², small against the motion's power, so the data take over within a few
        hundred samples.
    unit : float or None
        Metres per data unit (1.0 for samples in m, 1e-3 for mm); ``None``: inferred.
    p_max_factor : float
        Wind-up bound: max diag P ≤ p_max_factor · P₀ [-].
    """

    order: int = 24
    leads: int = 4
    correlated: bool = False
    forgetting_factor: float = 0.999
    delta: float = 1e-8
    unit: float | None = None
    p_max_factor: float = 10.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if int(self.order) != self.order or self.order < 2:
            raise ValueError(f"order must be an integer >= 2, got {self.order!r}")
        if int(self.leads) != self.leads or self.leads < 1:
            raise ValueError(f"leads must be a positive integer, got {self.leads!r}")
        if not 0.0 < self.forgetting_factor <= 1.0:
            raise ValueError(f"forgetting_factor must be in (0, 1], got {self.forgetting_factor}")
        if not self.delta > 0.0:
            raise ValueError(f"delta must be > 0 [m²], got {self.delta}")
        if not self.p_max_factor >= 1.0:
            raise ValueError(f"p_max_factor must be >= 1, got {self.p_max_factor}")


class PointsDelayLine(TappedDelayLine):
    """A :class:`TappedDelayLine` of stacked points whose rows may be partly measured.

    ``known`` marks the measured components; a row is *measured* (it may teach) only when
    all of them are. The gap repair of the base class reaches the filled components only: the
    measured ones are written back after every push.
    """

    def __init__(self, length: int, width: int) -> None:
        super().__init__(length, width)
        self.raw = np.zeros((int(length), int(width)))
        self.known = np.zeros((int(length), int(width)), dtype=bool)

    def push(self, z: np.ndarray, measured: bool = True, expected: np.ndarray | None = None,
             known: np.ndarray | None = None) -> bool:
        """:meth:`TappedDelayLine.push`; ``known`` (width,) marks the measured components
        (default: all of them if ``measured``, none otherwise)."""
        repaired = super().push(z, measured, expected)
        self.raw[1:] = self.raw[:-1]
        self.raw[0] = z
        self.known[1:] = self.known[:-1]
        self.known[0] = measured if known is None else known
        np.copyto(self.buf, self.raw, where=self.known)
        return repaired

    def retract(self, fill: np.ndarray, columns: slice = slice(None)) -> None:
        """The newest row's ``columns`` were an outlier: they become ``fill``'s."""
        row = self.buf[0].copy()
        row[columns] = fill[columns]
        super().retract(row)
        self.known[0, columns] = False


class SpatioTemporalRLS(Predictor):
    """Spatio-temporal RLS on the delay embedding of every tracked point (module docstring)."""

    Settings = SpatioTemporalSettings
    multi_point = True

    def _allocate(self, d: int) -> None:
        s = self.settings
        width = self.points * d
        batch = 1 if s.correlated else d
        self.rls = RecursiveLeastSquares(
            batch, (s.order - 1) * width // batch, s.leads * width // batch,
            s.forgetting_factor, s.delta / self.unit**2, s.p_max_factor, self.counts)
        self.line = PointsDelayLine(s.order + s.leads, width)
        self._held = np.full(width, np.nan)  # the newest measured value of each component

    # -- the model ----------------------------------------------------------------
    def _by_problem(self, a: np.ndarray) -> np.ndarray:
        """Rows (k, P·d) as the RLS problems' vectors: (1, k·P·d), or (d, k·P) per axis."""
        if self.settings.correlated:
            return a.reshape(1, -1)
        return a.reshape(a.shape[0], -1, self.d).transpose(2, 0, 1).reshape(self.d, -1)

    def _blocks(self, rows: np.ndarray) -> np.ndarray:
        """[r̂_{n+1}; …; r̂_{n+M}] as (M, P·d) from the newest-first rows (N, P·d)."""
        M = self.settings.leads
        out = self.rls.predict(self._by_problem(rows[1:] - rows[0]))  # (B, q)
        if not self.settings.correlated:  # (d, M·P) → (M, P, d)
            out = out.reshape(self.d, M, -1).transpose(1, 2, 0)
        return rows[0] + out.reshape(M, -1)

    def _next(self) -> np.ndarray:
        """r̂_{n+1} (P·d,) from the newest rows of the line."""
        return self._blocks(self.line.buf[: self.settings.order])[0]

    def _learn(self) -> None:
        """One RLS step on the M-delayed problem, if its N + M rows are all measured."""
        s, buf = self.settings, self.line.buf
        if self.line.real_run >= s.order + s.leads:
            past = buf[s.leads : s.leads + s.order]
            y = buf[s.leads - 1 :: -1] - past[0]  # leads 1 … M
            self.rls.update(self._by_problem(past[1:] - past[0]), self._by_problem(y))

    # -- the contract's hooks -----------------------------------------------------
    def _push_row(self, z: np.ndarray | None) -> None:
        """Push the row of this instant: measured values, and the model's fills for the rest."""
        d, line = self.d, self.line
        row = np.empty(line.buf.shape[1])
        row[:d] = np.nan if z is None else z
        row[d:] = self.others.reshape(-1)
        known = np.isfinite(row)
        self._held[known] = row[known]
        if known.all():
            expected = self._next() if line.fills and self.ready else None
            if line.push(row, expected=expected):
                self.counts["repaired"] += 1
            return
        if self.ready:
            fill = self._next()
        else:  # the newest value; a point never seen yet sits on the POI
            fill = np.where(np.isnan(self._held), np.resize(self._held[:d], row.size), self._held)
        row[~known] = fill[~known]
        line.push(row, measured=False, known=known)

    def _update(self, z: np.ndarray) -> None:
        self._push_row(z)
        self._learn()
        self.ready = self.line.filled >= self.settings.order

    def _missing(self) -> None:
        self._push_row(None)

    def _retract(self) -> bool:
        N = self.settings.order
        if self.line.real_run <= N:
            return False
        fill = self._blocks(self.line.buf[1 : N + 1])[0]
        self.line.retract(fill, slice(0, self.d))
        return True

    def _predict(self, steps: int) -> np.ndarray:
        N, M, d = self.settings.order, self.settings.leads, self.d
        blocks = -(-steps // M)
        hist = np.empty((blocks * M + N, self.line.buf.shape[1]))  # oldest rows last
        top = blocks * M
        hist[top:] = self.line.buf[:N]
        for _ in range(blocks):
            hist[top - M : top] = self._blocks(hist[top : top + N])[::-1]
            top -= M
        return hist[blocks * M - steps : blocks * M][::-1, :d].copy()
