"""Predictors on the sonomicrometer's streams: 3-step (about 23 ms) forecast RMS per replica.

The stream of ``benchmarks/predictor_streams.py`` (seed 4, every second sample of the 257-Hz
instrument, error against the measured sample, first 10 s not scored), written as a results
file. Quick: 2 replicas.

    python benchmarks/predictor_table.py [--quick]
"""

from __future__ import annotations

import argparse

import _results as R
from predictor_streams import NAMES, REPLICAS, one


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two replicas instead of six")
    a = ap.parse_args()
    replicas = REPLICAS[:2] if a.quick else REPLICAS
    data, rows = {}, []
    for name in replicas:
        _, out = one((name, False, 4, {}, list(NAMES), None, 0.0))
        data[name] = out
        best = min(out, key=lambda n: out[n]["meas"])
        rows.append([name, *[("**" + R.fmt(out[n]["meas"]) + "**") if n == best else
                             R.fmt(out[n]["meas"]) for n in NAMES]])
    tab = R.table(["replica", *[f"`{n}`" for n in NAMES]], rows)
    R.write("predictor_table", "Predictors on the sonomicrometer's streams",
            {"seed": 4, "replicas": data}, {"3-step forecast RMS [mm] (best in bold)": tab},
            a.quick)


if __name__ == "__main__":
    main()
