"""Horizon weights from forecast confidence against uniform weights.

The MPC's tracking cost weights every horizon point alike unless ``mpc.point_weights`` says
otherwise (``Q_k = tracking_weight · w_k / position_scale² · I``). A forecast is less certain
the further it reaches (Tuna et al. 2013, Fig. 8); with the predictor's running RMS miss per
lead ``e`` (``forecast_error_rms_mm`` of a run's document), :func:`confidence_weights` gives

    w_k ∝ 1 / (σ² + e(t_k)²),      t_k = k·Ts (k = 1 … N),   mean(w) = 1,

``e(t)`` interpolated linearly in lead time (held at the first lead's value before it), σ a
floor (the first lead's error: the nearest point weighs at most twice the mean-error point).
No paper weights the MPC this way. For each replica: a closed-loop run with uniform weights gives
``e``; the same run (same seed, same stream) is repeated with its weights. Prints both runs'
RMS/max error and effort.

    .venv/bin/python benchmarks/horizon_weights.py [--duration 60] [--preset]
"""

from __future__ import annotations

import argparse

import numpy as np

from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.paper.tables import COLUMNS

REPLICAS = COLUMNS  # Tuna et al. Tables I–III


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--predictor", default="generalized")
    ap.add_argument("--seed", type=int, default=3)
    ap.add_argument("--scenarios", default=",".join(REPLICAS))
    args = ap.parse_args()
    print(f"{args.predictor}, {args.duration:g} s, seed {args.seed}: RMS / max [mm], effort [mN·m]")
    print(f"{'scenario':16s} {'uniform':>26s} {'confidence':>26s}   weights first/last")
    for name in args.scenarios.split(","):
        base = RunConfig(predictor=args.predictor, scenario=name, seed=args.seed).replace(
            **{"loop.duration": args.duration, "loop.settling": min(20.0, args.duration / 3)})
        _, uniform = run_experiment(base)
        w = confidence_weights([e for e in uniform["forecast_error_rms_mm"] if e is not None],
                               uniform["forecast_lead_s"], base.loop.Ts, base.mpc.horizon)
        _, weighted = run_experiment(base.replace(**{"mpc.point_weights": w}))
        row = [f"{d['rms_error_mm']:.4f} / {d['max_error_mm']:.3f}, {d['rms_effort_mNm']:6.1f}"
               for d in (uniform, weighted)]
        print(f"{name:16s} {row[0]:>26s} {row[1]:>26s}   {w[0]:.2f}/{w[-1]:.2f}")


if __name__ == "__main__":
    main()
