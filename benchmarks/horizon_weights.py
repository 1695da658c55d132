"""Horizon weights from forecast confidence against uniform weights.

For each replica: a closed-loop run with uniform point weights gives the predictor's running RMS
miss per lead (``forecast_error_rms_mm``); :func:`rhmpc.control.confidence.confidence_weights`
turns it into ``w_k ∝ 1/(σ² + e_k²)``; the same run (same seed, same stream) is repeated with
those weights. Prints both runs' RMS/max error and effort.

    .venv/bin/python benchmarks/horizon_weights.py [--duration 60] [--preset]
"""

from __future__ import annotations

import argparse

from rhmpc.control.confidence import confidence_weights
from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.studies.paper import COLUMNS

REPLICAS = COLUMNS  # Tuna et al. Tables I–III


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
