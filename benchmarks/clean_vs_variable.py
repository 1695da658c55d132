"""Clean vs variable replicas: open-loop forecast error per predictor on the noise-free motion.

(a) 25 Hz, 3 samples (120 ms) ahead: RMS error / hold's (the predictability statistic of
    ``rhmpc.sim.heart.analysis.predictability``);
(b) Tuna et al.'s predictor rate, 2 kHz / 15 = 133.3 Hz, 4 samples (30 ms ≥ the 25 ms horizon)
    ahead: RMS error [mm].

60 s of each replica (seed 2), the first 20 s not scored. Run from the project root:

    .venv/bin/python benchmarks/clean_vs_variable.py     # ≈ 2 min
"""

from __future__ import annotations

import warnings

import numpy as np

from rhmpc.paper.tables import COLUMNS
from rhmpc.predictors import make_predictor
from rhmpc.sim.heart import make_scenario

NAMES = (*COLUMNS, "arrhythmia-apb")  # Tuna et al.'s six replicas and an arrhythmia
PREDICTORS = ("hold", "one-step", "generalized", "ekf", "dual-ekf", "ar", "last-cycle")
DURATION, SETTLE, SEED = 60.0, 20.0, 2


def rms_errors(z: np.ndarray, rate: float, ahead: int) -> dict[str, float]:
    """RMS of ‖ẑ_{n+ahead|n} − z_{n+ahead}‖ per predictor after ``SETTLE`` seconds."""
    out = {}
    for name in PREDICTORS:
        p = make_predictor(name, dt=1 / rate)
        sq = []
        for n in range(len(z) - ahead):
            p.update(z[n])
            if n >= round(SETTLE * rate) and p.ready:
                e = np.asarray(p.predict(ahead))[ahead - 1] - z[n + ahead]
                sq.append(float(e @ e))
        out[name] = float(np.sqrt(np.mean(sq)))
    return out


def main() -> None:
    warnings.filterwarnings("ignore")
    print("left: RMS error / hold at 25 Hz, 120 ms; right: RMS error [mm] at 133 Hz, 30 ms")
    print(f"{'':25s} | " + " ".join(f"{p:>11s}" for p in PREDICTORS))
    for name in NAMES:
        for label, kw in (("clean", {"variability": "clean"}), ("variable", {})):
            sc = make_scenario(name, np.random.default_rng(SEED), duration=DURATION, **kw)
            cells = []
            for rate, ahead in ((25.0, 3), (2000 / 15, 4)):
                t = np.arange(round(DURATION * rate) + 1) / rate
                cells.append(rms_errors(sc.source.position(t), rate, ahead))
            a, b = cells
            print(f"{name:16s} {label:8s} | "
                  + " ".join(f"{a[k] / a['hold']:5.3f}/{1e3 * b[k]:5.3f}" for k in PREDICTORS),
                  flush=True)


if __name__ == "__main__":
    main()
