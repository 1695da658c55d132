"""Forecast RMS of every predictor on the in-vivo regime and the Tuna replicas at 25 Hz.

The protocol of the ``invivo-regime`` check: each scenario's true motion sampled at 25 Hz for
60 s (seed 2), every sample fed, forecasts from sample 300 on scored against the motion 1, 3 and
5 samples later (3-D RMS, mm).  Rows: each predictor with its default parameters, and, as
``name:set``, its other parameter sets (the papers' protocols, and the sets without the
non-periodic part).  Prints a markdown table (``--json`` for the numbers).

    .venv/bin/python benchmarks/invivo_regime.py [--seed 2] [--seconds 60] [--json]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from rhmpc.paper.tables import COLUMNS
from rhmpc.predictors import make_predictor
from rhmpc.predictors.monitor import rms_by_lead
from rhmpc.sim.heart import make_scenario

SCENARIOS = ("invivo-video", *COLUMNS)
ROWS = ("hold", "last-cycle", "last-cycle:yuen2008", "one-step", "generalized", "ekf",
        "ekf:tuna2013-hrv", "dual-ekf", "dual-ekf:fitted", "ar", "fading-ar", "wflc", "wflc:pll")
RATE, WARMUP, LEADS = 25.0, 300, (1, 3, 5)


def score(row: str, z: np.ndarray) -> list[float]:
    """RMS [mm] at each of ``LEADS`` of predictor ``row`` (``name`` or ``name:params``)."""
    name, _, params = row.partition(":")
    p = make_predictor(name, 1.0 / RATE, **({"params": params} if params else {}))
    rms = 1e3 * rms_by_lead(p, z, max(LEADS), WARMUP)
    return [float(rms[k - 1]) for k in LEADS]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    t = np.arange(round(a.seconds * RATE) + 1) / RATE
    res = {}
    for s in SCENARIOS:
        z = make_scenario(s, np.random.default_rng(a.seed)).source.position(t)
        res[s] = {row: score(row, z) for row in ROWS}
    if a.json:
        print(json.dumps(res, indent=1))
        return
    print("| predictor | " + " | ".join(SCENARIOS) + " |")
    print("|---" * (len(SCENARIOS) + 1) + "|")
    for row in ROWS:
        cells = []
        for s in SCENARIOS:
            v, h = res[s][row], res[s]["hold"]
            mark = "" if row == "hold" or all(x < y for x, y in zip(v, h, strict=True)) else " ✗"
            cells.append(" / ".join(f"{x:.2f}" for x in v) + mark)
        print(f"| `{row}` | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
