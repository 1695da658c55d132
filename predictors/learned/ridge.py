"""Ridge regression on the delay embedding: the batch linear predictor fitted before the run.

One direct linear model per lead k = 1 … L (Ben Taieb et al. 2012, "A review and comparison
of strategies for multi-step ahead time series forecasting", Expert Syst. Appl. 39:7067) on
the increment form of the delay embedding of every tracked point (``st-ridge``) or of the POI
only (``ridge``), as :mod:`rhmpc.predictors.rls_spatiotemporal` adapts online:

    ẑ_{n+k} = z_n + W_k x_n,   x_n = [r_{n−1} − r_n; …; r_{n−N+1} − r_n],

r_n the stacked samples of the points at instant n. W = [W_1; …; W_L] minimises the ridge
cost (Hoerl & Kennard 1970)

    Σ_n ‖y_n − W x_n‖² + α m s̄² ‖W‖²_F,   y_n = [z_{n+1} − z_n; …; z_{n+L} − z_n],

over the m training samples whose window and targets are all measured, s̄² the mean power of
a regressor: α is relative, free of the data's unit and size. The window N and α of
each lead are chosen by forward validation (Bergmeir & Benítez 2012, "On the use of
cross-validation for time series predictor evaluation", Inf. Sci. 191:192): fitted on each
series' first part, scored on the forecasts issued from its last ``validation`` fraction, the
pair of least mean squared error at that lead is refitted on everything.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rhmpc import io
from rhmpc.io import FileError
from rhmpc.predictors.base import PredictorSettings
from rhmpc.predictors.learned.fitted import FittedPredictor
from rhmpc.predictors.learned.series import relative_windows

__all__ = ["MultiPointRidge", "Ridge", "RidgeSettings"]


@dataclass(frozen=True)
class RidgeSettings(PredictorSettings):
    """Settings of the ridge predictors.

    Attributes
    ----------
    leads : int
        L, leads with their own model [samples]; 4 (160 ms at 25 frames/s, the literature's
        4-step horizon); a longer forecast holds the lead-L one.
    windows : tuple of float
        Candidate spans of the delay window [s], N = max(2, round(span/dt)) samples: half,
        one and two cardiac cycles at 60 beats/min, the span a linear predictor needs to see
        the periodic motion (one cycle) and its beat-to-beat repetition (two).
    alphas : tuple of float
        Candidate relative ridge weights α [-], a decade apart from 1e-6 (≈ least squares) to
        1 (≈ the hold).
    validation : float
        Fraction of each training series held out to choose (N, α) [-]; 0.2, the last fifth
        (forecasts issued there; their windows may reach back into the fitting part).
    unit : float or None
        Metres per data unit of the online samples (1.0 for m, 1e-3 for mm); ``None``:
        inferred.
    model : str or None
        A file written by ``save`` to load at construction.
    """

    leads: int = 4
    windows: tuple[float, ...] = (0.5, 1.0, 2.0)
    alphas: tuple[float, ...] = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0)
    validation: float = 0.2
    unit: float | None = None
    model: str | None = None

    def __post_init__(self) -> None:
        super().__post_init__()
        if int(self.leads) != self.leads or self.leads < 1:
            raise ValueError(f"leads must be a positive integer, got {self.leads!r}")
        if not self.windows or not all(w > 0 and np.isfinite(w) for w in self.windows):
            raise ValueError(f"windows must be spans > 0 [s], got {self.windows!r}")
        if not self.alphas or not all(a >= 0 and np.isfinite(a) for a in self.alphas):
            raise ValueError(f"alphas must be >= 0, got {self.alphas!r}")
        if not 0.0 < self.validation < 1.0:
            raise ValueError(f"validation must be in (0, 1), got {self.validation!r}")


def _samples(rows: np.ndarray, order: int, leads: int, d: int) -> tuple[np.ndarray, ...]:
    """Regressors (m, n), targets (m, L·d) and origins of the usable samples of one series."""
    T = rows.shape[0]
    if T < order + leads:
        return np.empty((0, (order - 1) * rows.shape[1])), np.empty((0, leads * d)), np.empty(0)
    x = relative_windows(rows[: T - leads], order)  # origins n = N − 1 … T − L − 1
    n = np.arange(order - 1, T - leads)
    poi = rows[:, :d]
    y = np.concatenate([poi[n + k] - poi[n] for k in range(1, leads + 1)], axis=1)
    ok = np.isfinite(x).all(axis=1) & np.isfinite(y).all(axis=1)
    return x[ok], y[ok], n[ok]


def _ridge(x: np.ndarray, y: np.ndarray, alphas) -> list[np.ndarray]:
    """W (q, n) per α, one SVD: W = Y' U diag(s/(s² + α m s̄²)) Vᵀ."""
    u, s, vt = np.linalg.svd(x, full_matrices=False)
    power = float(np.mean(x**2)) or 1.0
    uy = u.T @ y
    return [((vt.T * (s / (s**2 + a * x.shape[0] * power))) @ uy).T for a in alphas]


class Ridge(FittedPredictor):
    """Ridge regression on the POI's delay embedding (module docstring)."""

    Settings = RidgeSettings
    KIND = "ridge"

    def _fit(self, series: list[np.ndarray], progress) -> dict:
        s, d, L = self.settings, series[0].shape[2], self.settings.leads
        orders = sorted({max(2, round(w / self.dt)) for w in s.windows})
        m, width = sum(a.shape[0] for a in series), series[0].shape[1] * d
        io.check("window", orders[-1], "windows", memory_scale=3 * m * width)
        best: list[tuple] = [(np.inf, 0, 0.0)] * L  # per lead: (validation MSE, N, α)
        for N in orders:
            fit, val = [], []
            for a in series:
                rows = a.reshape(a.shape[0], -1)
                cut = round((1.0 - s.validation) * rows.shape[0])
                x, y, n = _samples(rows, N, L, d)
                fit.append((x[n + L < cut], y[n + L < cut]))
                val.append((x[n >= cut], y[n >= cut]))
            xf, yf = (np.concatenate(v) for v in zip(*fit, strict=True))
            xv, yv = (np.concatenate(v) for v in zip(*val, strict=True))
            if xf.shape[0] < 2 or xv.shape[0] < 1:
                continue
            for alpha, W in zip(s.alphas, _ridge(xf, yf, s.alphas), strict=True):
                e = (yv - xv @ W.T).reshape(-1, L, d)
                mse = np.mean(np.sum(e**2, axis=2), axis=0)  # per lead
                best = [b if b[0] <= m else (m, N, alpha) for b, m in zip(best, mse,
                                                                           strict=True)]
            if progress is not None:
                progress(f"window {N} samples: validated")
        if not np.isfinite(best[0][0]):
            raise ValueError(f"too little data to fit: every window ({orders} samples) leaves "
                             "no complete sample to validate on")
        W = []
        for k, (_, N, alpha) in enumerate(best):
            x, y = (np.concatenate(v) for v in zip(
                *[_samples(a.reshape(a.shape[0], -1), N, L, d)[:2] for a in series],
                strict=True))
            W.append(_ridge(x, y[:, k * d : (k + 1) * d], [alpha])[0])
        if progress is not None:
            progress("windows " + ", ".join(str(b[1]) for b in best) + " samples, alphas "
                     + ", ".join(f"{b[2]:g}" for b in best) + " per lead")
        return {"orders": np.array([b[1] for b in best]), "alphas": np.array([b[2] for b in best]),
                "W": W, "validation_rms": np.sqrt([b[0] for b in best])}

    def _span(self) -> int:
        return int(max(self.model["orders"]))

    def _forecast(self) -> np.ndarray:
        rows, d = self._rows, self.d
        rel = rows[1:] - rows[0]
        return rows[0, :d] + np.stack([W @ rel[: N - 1].reshape(-1) for N, W in
                                       zip(self.model["orders"], self.model["W"], strict=True)])

    # -- the model's file ------------------------------------------------------------
    def _arrays(self) -> dict[str, np.ndarray]:
        m = self.model
        return {"orders": np.asarray(m["orders"], dtype=np.int64), "alphas": m["alphas"],
                "validation_rms": m["validation_rms"],
                **{f"W{k}": W for k, W in enumerate(m["W"])}}

    def model_shapes(self, settings, saved):
        """W_k is (d, (N_k − 1)·P·d) for the window N_k of lead k (``orders``, read first and
        bounded: 2 ≤ N_k and the online history of N_k rows fits, :data:`rhmpc.io.BOUNDS`)."""
        L, d = settings.leads, saved.dim
        width = (saved.points if self.multi_point else 1) * d
        saved.expect({"orders": (L,)}, tuple(n for n in saved.shapes if n != "orders"))
        orders = saved.read("orders")
        if orders.dtype.kind != "i" or np.any(orders < 2) or np.any(
                orders > io.largest("window", width)):
            raise FileError(f"{saved.path}: the model's windows {orders.tolist()} are not "
                            f"between 2 and {io.largest('window', width)} samples")
        shapes = {"orders": (L,), "alphas": (L,), "validation_rms": (L,)}
        shapes.update({f"W{k}": (d, (int(N) - 1) * width) for k, N in enumerate(orders)})
        return shapes, ()

    def _restore(self, settings, arrays, saved) -> dict:
        orders = arrays["orders"]
        return {"W": [arrays[f"W{k}"] for k in range(orders.size)], "orders": orders,
                "alphas": arrays["alphas"], "validation_rms": arrays["validation_rms"]}


class MultiPointRidge(Ridge):
    """Ridge regression on the delay embedding of every tracked point (module docstring)."""

    KIND = "st-ridge"
    multi_point = True
