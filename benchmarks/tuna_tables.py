"""Tuna et al. 2013 Tables I and III beside ours: ``rhmpc compare --preset tuna2013``.

Every published cell (RMS and max position error, RMS effort) next to ours and the ratio
ours / paper, for the four predictors on the six replicas. Writes ``docs/results/tuna_tables``.

    python benchmarks/tuna_tables.py [--quick] [--seed 3]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import _results as R

from rhmpc.studies.paper import COLUMNS, TUNA2013

PREDICTORS = ("exact", "one-step", "generalized", "ekf")
METRICS = {"rms_error_mm": ("RMS position error [mm]", 3),
           "max_error_mm": ("maximum error [mm]", 3),
           "rms_effort_mNm": ("RMS control effort [mN·m]", 1)}
SHORT = {"fixed-a1-top": "fixed a1", "fixed-a2-top": "fixed a2", "varying-a1-top": "var. a1",
         "varying-a3-top": "var. a3", "varying-a1-side": "var. a1 side",
         "varying-a3-side": "var. a3 side"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="20-s runs instead of 60-s")
    ap.add_argument("--seed", type=int, default=3)
    a = ap.parse_args()
    duration = 20.0 if a.quick else 60.0
    cmd = [sys.executable, "-m", "rhmpc.cli", "compare", "--preset", "tuna2013",
           "--predictors", ",".join(PREDICTORS), "--duration", f"{duration:g}",
           "--seed", str(a.seed), "--jobs", "1", "--json"]
    docs = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    ours = {(d["predictor"], d["scenario"]): d for d in docs}
    cells, tables = [], {}
    for (tab, metric), published in TUNA2013.items():
        label, digits = METRICS[metric]
        rows = []
        for pred in PREDICTORS:
            paper_row, ours_row = [f"`{pred}`", "paper"], ["", "ours"]
            ratio_row = ["", "ours ÷ paper"]
            for col in COLUMNS:
                paper = published.get(pred, {}).get(col)
                mine = ours[(pred, col)][metric]
                ratio = None if paper is None else mine / paper
                cells.append({"table": tab, "metric": metric, "predictor": pred,
                              "scenario": col, "paper": paper, "ours": mine, "ratio": ratio})
                paper_row.append(R.fmt(paper, digits))
                ours_row.append(f"**{R.fmt(mine, digits)}**")
                ratio_row.append(R.fmt(ratio, 2))
            rows += [paper_row, ours_row, ratio_row]
        head = "Table I (simulation)" if tab == "I" else "Table III (experiments)"
        tables[f"{head}: {label}"] = R.table(["predictor", "", *[SHORT[c] for c in COLUMNS]],
                                             rows)
    R.write("tuna_tables", "Tuna et al. 2013 Tables I and III", {
        "command": " ".join(["rhmpc", *cmd[3:]]), "duration_s": duration, "seed": a.seed,
        "cells": cells}, tables, a.quick,
        notes="A dash: the paper has no such cell (its Table I has no EKF row). Ours: "
              "`rhmpc compare --preset tuna2013`, the physical sonomicrometer, causal delivery, "
              "the error scored against the recorded stream as in the paper.")


if __name__ == "__main__":
    main()
