"""Autoregressive model of what a periodic model leaves: the residual that follows the
non-periodic motion sample to sample.

A Fourier-series predictor fits the quasi-periodic part of the motion; in vivo most of the
motion is not periodic (beat-to-beat changes of shape, amplitude and timing), and a forecast
from the periodic part alone misses it by as much as it is. The residual of the model's
current state over the last p + 1 samples,

    e_{n−j} = z_{n−j} − ŷ_{n−j|n},   j = 0 … p,

(ŷ_{t|n} the model with its newest state, evaluated at sample t, past or future) is followed
by a per-axis autoregression fitted by exponentially weighted RLS (the kernel of
:mod:`rhmpc.predictors.rls`; the one-step predictor of Tuna et al. 2013 §V, run on e instead of z):

    ê_{n+1} = Σ_{i=1}^{p} a_i e_{n+1−i},    a ← RLS(λ, δ) on (e_{n−1…n−p} ↦ e_n),
    a⁰ = (1, 0, …, 0),

forecasts iterating it. The predictor's forecast is the model's plus ê:

    ẑ_{n+k} = ŷ_{n+k|n} + ê_{n+k|n}.

The residuals are those of the *current* state, recomputed at each sample, so a correction
or a re-fit of the model moves the whole history with it and ẑ stays anchored at the newest
sample. With a⁰ = (1, 0, …) the residual persists: ẑ_{n+1} = z_n + (ŷ_{n+1|n} − ŷ_{n|n}), the
newest sample plus the model's increment; RLS then learns how the residual decays and
oscillates. A missing sample (NaN) has residual 0 (the model's own value) and no window
holding one is learnt from.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from rhmpc.predictors.rls import RecursiveLeastSquares

__all__ = ["RecentSamples", "ResidualAR"]


class RecentSamples:
    """The last ``n`` samples, newest first; NaN rows for missing (or rejected) samples."""

    def __init__(self, n: int, d: int) -> None:
        self.z = np.full((int(n), int(d)), np.nan)

    def push(self, z: np.ndarray | float) -> None:
        self.z[1:] = self.z[:-1]
        self.z[0] = z

    def clear(self) -> None:
        self.z[:] = np.nan


class ResidualAR:
    """Per-axis AR(p) model of a residual, fitted by RLS (module docstring).

    Parameters
    ----------
    d : int
        Axes.
    order : int
        p, lags of the autoregression [-].
    forgetting_factor : float
        λ of the RLS [-].
    delta : float
        Prior weight δ of the RLS, in data units² (``P₀ = I/δ``).
    counts : Counter, optional
        Where the RLS guards are counted.
    """

    #: a forecast beyond this multiple of the largest recent residual magnitude is unstable [-]
    GROWTH = 3.0

    def __init__(self, d: int, order: int, forgetting_factor: float, delta: float,
                 counts: Counter | None = None) -> None:
        self.d, self.p = int(d), int(order)
        self.rls = RecursiveLeastSquares(d, self.p + 1, 1, forgetting_factor, delta,
                                         counts=counts)
        self.rls.W[:, 0, 0] = 1.0  # a⁰ = (1, 0, …): persistence; b⁰ = 0: the model's increment

    def restart(self, variance: np.ndarray, samples: float) -> None:
        """Prior at the current weights worth ``samples`` residuals of ``variance`` (d,) each:
        P ← I/(samples·variance) per axis (after a fit of the model: its residual variance)."""
        for a in range(self.d):
            self.rls.P[a] = np.eye(self.p + 1) / max(samples * float(variance[a]), 1e-300)

    def learn(self, e: np.ndarray, u: np.ndarray) -> None:
        """One RLS step on the residuals ``e`` (p + 1, d), newest first, with the model's
        increment u_n = ŷ_{n|n} − ŷ_{n−1|n} (d,) (skipped if any NaN)."""
        if np.isfinite(e).all():
            x = np.empty((self.d, self.p + 1))
            x[:, : self.p] = e[1:].T
            x[:, self.p] = u
            self.rls.update(x, e[0][:, None])

    def forecast(self, e: np.ndarray, u: np.ndarray, steps: int) -> np.ndarray:
        """ê_{n+1…n+steps} (steps, d) from residuals ``e`` (≥ p, d), newest first (NaN → 0),
        and the model's increments u_{n+k} = ŷ_{n+k|n} − ŷ_{n+k−1|n} (steps, d).

        An axis whose forecast leaves ``GROWTH`` times the largest recent magnitude of e (an
        unstable fit of few samples) persists its newest residual instead (counted
        ``residual_unstable``).
        """
        a, b = self.rls.W[:, 0, : self.p], self.rls.W[:, 0, self.p]  # (d, p), (d,)
        buf = np.zeros((steps + self.p, self.d))
        buf[steps:] = np.nan_to_num(e[: self.p], nan=0.0)
        for k in range(steps - 1, -1, -1):
            buf[k] = np.einsum("ap,pa->a", a, buf[k + 1 : k + 1 + self.p]) + b * u[steps - 1 - k]
        out = buf[:steps][::-1].copy()
        bound = self.GROWTH * np.max(np.abs(buf[steps:]), axis=0)
        wild = np.any(np.abs(out) > bound, axis=0)
        if wild.any():
            self.rls.counts["residual_unstable"] += 1
            out[:, wild] = buf[steps, wild]
        return out
