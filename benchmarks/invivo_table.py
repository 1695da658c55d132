"""Every predictor on the in-vivo regime and the Tuna replicas at 25 Hz, against hold.

The protocol of :mod:`invivo_regime` (true motion at 25 Hz, seed 2, every sample fed,
forecasts from sample 300 on scored 1, 3 and 5 samples ahead, 3-D RMS in mm) for each
predictor's default parameter set, and for the predictors whose default adds a part for motion
that is not periodic (``docs/validation/predictors.md``), their set without it, written as a
results file. Quick: 30 s, the in-vivo regime and two replicas.

    python benchmarks/invivo_table.py [--quick]
"""

from __future__ import annotations

import argparse

import _results as R
import numpy as np
from invivo_regime import LEADS, RATE, SCENARIOS, score

from rhmpc.sim.heart import make_scenario

PREDICTORS = ("hold", "last-cycle", "one-step", "generalized", "ekf", "dual-ekf", "ar",
              "fading-ar", "wflc")
#: Each default set with a part for motion that is not periodic, and its set without it.
WITHOUT = ("last-cycle:yuen2008", "ekf:tuna2013-hrv", "dual-ekf:fitted", "wflc:pll")
SHORT = {"invivo-video": "in vivo", "fixed-a1-top": "fixed a1", "fixed-a2-top": "fixed a2",
         "varying-a1-top": "var. a1", "varying-a3-top": "var. a3",
         "varying-a1-side": "var. a1 side", "varying-a3-side": "var. a3 side"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="30 s and three scenarios")
    a = ap.parse_args()
    seconds, scenarios = (30.0, SCENARIOS[:3]) if a.quick else (60.0, SCENARIOS)
    t = np.arange(round(seconds * RATE) + 1) / RATE
    data = {}
    for s in scenarios:
        z = make_scenario(s, np.random.default_rng(2)).source.position(t)
        data[s] = {p: score(p, z) for p in (*PREDICTORS, *WITHOUT)}

    def table(names):
        return R.table(["predictor", *[SHORT[s] for s in scenarios]], [
            [f"`{p}`", *[" / ".join(R.fmt(v, 2) for v in data[s][p]) for s in scenarios]]
            for p in names])

    leads = " / ".join(map(str, LEADS))
    R.write("invivo_table", "Predictors on the in-vivo regime and the replicas at 25 Hz",
            {"seed": 2, "seconds": seconds, "rate_hz": RATE, "leads": list(LEADS),
             "rms_mm": data},
            {f"forecast RMS [mm] at {leads} samples ahead": table(PREDICTORS),
             f"sets|the sets without the part for motion that is not periodic, forecast RMS "
             f"[mm] at {leads} samples ahead": table(WITHOUT)}, a.quick,
            notes="Each scenario's true motion sampled at 25 frames/s, every sample fed; "
                  "the default parameter set of each predictor (in the second table the set "
                  "named after the colon); the first 300 samples not scored.")


if __name__ == "__main__":
    main()
