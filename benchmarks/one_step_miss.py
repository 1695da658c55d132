"""One-step miss of a predictor behind the loop's gate, on each replica's sensor stream.

The miss ‖z_{n+1} − ẑ_{n+1|n}‖ that the outlier gate tests, over 60 s of the closed loop's
open-loop part (``rhmpc.experiment.build_run``: same sensor, delivery, gate; driven as in
``reference_bench.py``), from 10 s on. Its RMS sets the gate's floor (4σ).

    .venv/bin/python benchmarks/one_step_miss.py [--predictor generalized] [--seed 0]
"""

from __future__ import annotations

import argparse

import numpy as np
from reference_bench import SCENARIOS, drive  # benchmarks/, this script's directory


def misses(scenario: str, predictor: str, seed: int) -> np.ndarray:
    """One-step misses [mm] of ``predictor`` on ``scenario``'s 60-s stream, after 10 s."""
    changes = {"scenario": scenario, "seed": seed, "predictor": predictor,
               "loop.duration": 60.0, "loop.settling": 10.0}
    out = []
    for _, _, arrivals in drive(changes):
        for z, stamp, forecast in arrivals:
            if z is not None and forecast is not None and stamp > 10.0:
                out.append(np.linalg.norm(z - forecast))
    m = 1e3 * np.asarray(out)
    return m[np.isfinite(m)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--predictor", default="generalized")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    for scenario in SCENARIOS:
        m = misses(scenario, a.predictor, a.seed)
        print(f"{scenario:<16} one-step miss RMS {np.sqrt(np.mean(m**2)):.4f} mm, median "
              f"{np.median(m):.4f}, p99 {np.percentile(m, 99):.3f}")


if __name__ == "__main__":
    main()
