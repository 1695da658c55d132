"""Strict heart-rate lock feasibility: a tracker that knows the true rate, one beat late.

For every replica (seed 4, 60 s, scored 15–59 s) and the same replicas driven by MIT-BIH record
100, prints the range of the true rate and the error of that oracle. A beat's rate is known only
once the beat has ended, so the change between consecutive beats bounds what any causal
estimator can follow at a beat's start.

    .venv/bin/python benchmarks/lock_bound.py [--record mitdb-100]
"""

from __future__ import annotations

import argparse

import numpy as np

from rhmpc.paper.tables import COLUMNS
from rhmpc.sim.heart import make_scenario

REPLICAS = COLUMNS  # Tuna et al. Tables I–III


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--record", default="mitdb-100")
    a = ap.parse_args()
    for rr in (None, a.record):
        for name in REPLICAS:
            kw = {"duration": 60.0} | ({"record": rr} if rr else {})
            rate = make_scenario(name, np.random.default_rng(4), **kw).source.phase.rate
            t = np.arange(15.0, 59.0, 0.0075)
            bpm = 60.0 * np.array([float(rate(x)) for x in t])
            late = 60.0 * np.array([float(rate(x - 60.0 / b)) for x, b in zip(t, bpm, strict=True)])
            e = np.abs(late - bpm)
            kind = "rr" if rr else "variable"
            print(f"{kind:<9}{name:<16} rate {bpm.min():5.1f}–{bpm.max():5.1f} bpm;"
                  f" one beat late: max {e.max():4.1f}, p95 {np.percentile(e, 95):4.1f}, "
                  f"within 5 bpm {np.mean(e < 5):.3f}")


if __name__ == "__main__":
    main()
