"""Horizon weights from the predictor's forecast confidence (an option).

The MPC's tracking cost weights every horizon point alike unless ``MPCSettings.point_weights``
says otherwise (``Q_k = tracking_weight · w_k / position_scale² · I``). A forecast is less
certain the further it reaches (Tuna et al. 2013, Fig. 8), so a point the predictor misses by
``e_k`` on average can be trusted less. With the predictor's running RMS miss per lead
(``Predictor.forecast_error_rms``, in the result document as ``forecast_error_rms_mm``),

    w_k ∝ 1 / (σ² + e(t_k)²),      t_k = k·Ts (k = 1 … N),   mean(w) = 1

where ``e(t)`` interpolates the per-lead errors linearly in lead time (held at the first lead's
value before it) and ``σ`` is a floor (default: the first lead's error, so the nearest point
weighs at most twice the mean-error point). The weights enter ``P``, so they are a build-time
setting — the QP, its screening maps and the C export are rebuilt from them, and every tick
stays a vector-only update. No paper weights the MPC this way; the README reports the measured
effect against uniform weights.
"""

from __future__ import annotations

import numpy as np


def confidence_weights(errors: np.ndarray, lead_step: float, Ts: float, horizon: int,
                       sigma: float | None = None) -> tuple[float, ...]:
    """Point weights ``w_k ∝ 1/(σ² + e(kTs)²)`` with mean 1, for ``MPCSettings.point_weights``.

    Parameters
    ----------
    errors : (K,) array
        RMS forecast miss at leads ``lead_step · (1 … K)`` (any length unit; NaN not allowed).
    lead_step : float
        Time between the predictor's forecast points [s] (``downsample · Ts``).
    Ts : float
        Control period [s].
    horizon : int
        N, the number of horizon points.
    sigma : float, optional
        Floor σ in the units of ``errors`` (default ``errors[0]``).

    Raises
    ------
    ValueError
        On empty, negative or non-finite errors, or a non-positive floor.
    """
    e = np.asarray(errors, dtype=float)
    if e.ndim != 1 or e.size == 0 or not np.all(np.isfinite(e)) or np.any(e < 0):
        raise ValueError(f"errors must be a non-empty finite non-negative vector, got {errors!r}")
    floor = float(e[0]) if sigma is None else float(sigma)
    if not floor > 0 or not np.isfinite(floor):
        raise ValueError(f"the floor sigma must be > 0, got {floor!r}")
    leads = lead_step * np.arange(1, e.size + 1)
    e_k = np.interp(Ts * np.arange(1, int(horizon) + 1), leads, e)
    w = 1.0 / (floor**2 + e_k**2)
    return tuple(float(v) for v in w / w.mean())
