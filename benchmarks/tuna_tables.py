"""Tuna et al. 2013 Tables I–III beside ours, and their findings, from the two presets.

Table I is a simulation: ``rhmpc compare --preset tuna2013`` (the MPC's linear model as the
plant). Tables II–III are hardware experiments: ``rhmpc compare --preset tuna2013-hardware`` (the
hardware-like PHANToM, the error from the encoders' forward kinematics). Every published cell,
ours (the max over the seeds, Tuna's statistic) and the ratio ours / paper; then one line per
published finding, reproduced or not, with the measured cause (``rhmpc.studies.paper``). Writes
``docs/results/tuna_tables``.

    python benchmarks/tuna_tables.py [--quick] [--seed 3]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import _results as R

from rhmpc.studies.paper import COLUMNS, SETTING, TUNA2013, findings, hardware_effort_finding

#: The runs of each setting: the preset and the predictors it is compared on.
RUNS = {"simulation": ("tuna2013", ("exact", "one-step", "generalized")),
        "hardware": ("tuna2013-hardware", ("exact", "one-step", "generalized", "ekf"))}
METRICS = {"rms_error_mm": ("RMS position error [mm]", 3),
           "max_error_mm": ("maximum error [mm]", 3),
           "rms_effort_mNm": ("RMS control effort [mN·m]", 1)}
TITLES = {"I": "Table I (simulation)", "II": "Table II (hardware experiments)",
          "III": "Table III (hardware experiments, EKF)"}
SHORT = {"fixed-a1-top": "fixed a1", "fixed-a2-top": "fixed a2", "varying-a1-top": "var. a1",
         "varying-a3-top": "var. a3", "varying-a1-side": "var. a1 side",
         "varying-a3-side": "var. a3 side"}


def compare(preset: str, predictors, duration: float, seed: int) -> tuple[list, list[str]]:
    """The documents of ``rhmpc compare --preset PRESET`` and its command line."""
    cmd = [sys.executable, "-m", "rhmpc.cli", "compare", "--preset", preset,
           "--predictors", ",".join(predictors), "--duration", f"{duration:g}",
           "--seed", str(seed), "--jobs", "1", "--json"]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    return json.loads(out), ["rhmpc", *cmd[3:]]


def tables_of(docs: dict, cells: list) -> dict[str, str]:
    """Every published table beside the runs of its own setting."""
    out = {}
    for (tab, metric), published in TUNA2013.items():
        ours = {(d["predictor"], d["scenario"]): d for d in docs[SETTING[tab]]}
        label, digits = METRICS[metric]
        rows = []
        for pred, paper_cells in published.items():
            paper_row, ours_row, ratio_row = [f"`{pred}`", "paper"], ["", "ours"], ["", "÷"]
            for col in COLUMNS:
                paper, mine = paper_cells[col], ours[(pred, col)][metric]
                cells.append({"table": tab, "metric": metric, "predictor": pred,
                              "scenario": col, "paper": paper, "ours": mine,
                              "ratio": mine / paper})
                paper_row.append(R.fmt(paper, digits))
                ours_row.append(f"**{R.fmt(mine, digits)}**")
                ratio_row.append(R.fmt(mine / paper, 2))
            rows += [paper_row, ours_row, ratio_row]
        out[f"{TITLES[tab]}: {label}"] = R.table(
            ["predictor", "", *[SHORT[c] for c in COLUMNS]], rows)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="20-s runs instead of 60-s")
    ap.add_argument("--seed", type=int, default=3)
    a = ap.parse_args()
    duration = 20.0 if a.quick else 60.0
    docs, commands = {}, []
    for setting, (preset, predictors) in RUNS.items():
        docs[setting], command = compare(preset, predictors, duration, a.seed)
        commands.append(" ".join(command))
    cells: list = []
    tables = tables_of(docs, cells)
    lines = [f"{setting}: {line}" for setting in RUNS
             for line in findings(docs[setting], setting, COLUMNS)
             if "not measured here" not in line]
    lines.append("both: " + hardware_effort_finding(docs["simulation"], docs["hardware"],
                                                    COLUMNS))
    R.write("tuna_tables", "Tuna et al. 2013 Tables I–III", {
        "command": " ; ".join(commands), "duration_s": duration, "seed": a.seed,
        "cells": cells, "findings": lines}, tables, a.quick,
        notes="Ours: the physical sonomicrometer with its white range error, causal delivery, "
              "the error scored against the recorded stream as in the paper. Table I beside "
              "the simulation preset, Tables II–III beside the hardware preset; a simulation is "
              "never set against a hardware table. The findings, as `rhmpc compare --paper` "
              "prints them:\n\n```text\n" + "\n".join(lines) + "\n```")


if __name__ == "__main__":
    main()
