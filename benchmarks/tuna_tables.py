"""Tuna et al. 2013 Tables I–III beside ours, and their findings, from the two presets.

Table I is a simulation: ``rhmpc compare --preset tuna2013`` (the MPC's linear model as the
plant). Tables II–III are hardware experiments: ``rhmpc compare --preset tuna2013-hardware`` (the
hardware-like PHANToM, the error from the encoders' forward kinematics). Every published cell,
ours (the max over the seeds, Tuna's statistic) and the ratio ours / paper; then one line per
published finding, reproduced or not, with the measured cause (``rhmpc.studies.paper``).

Tuna ran the two RLS predictors at different orders (§VIII-B: a 16th-order one-step predictor,
a 10th-order generalized one), so the tables also set them against each other at equal order:
both at N = 16 and both at N = 10, on the same columns, presets and seed (the runs at a
predictor's own order are the tables' runs). Writes ``docs/results/tuna_tables``.

    python benchmarks/tuna_tables.py [--quick] [--seed 3]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import _results as R
import numpy as np

from predictors import settings_for
from rhmpc.studies.paper import COLUMNS, SETTING, TUNA2013, findings, hardware_effort_finding, ours

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
#: The equal-order comparison: the two RLS predictors, both at each of these orders N.
RLS = ("one-step", "generalized")
ORDERS = (16, 10)


def compare(preset: str, predictors, duration: float, seed: int,
            sets: tuple[str, ...] = ()) -> tuple[list, list[str]]:
    """The documents of ``rhmpc compare --preset PRESET [--set …]`` and its command line."""
    cmd = [sys.executable, "-m", "rhmpc.cli", "compare", "--preset", preset,
           "--predictors", ",".join(predictors), "--duration", f"{duration:g}",
           "--seed", str(seed), "--jobs", "1", "--json"]
    for item in sets:
        cmd += ["--set", item]
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


def order_of(doc: dict) -> int:
    """The order N that an RLS predictor's run ran with (its settings over the defaults)."""
    return settings_for(doc["predictor"], **doc["settings"].get("predictor_settings", {})).order


def equal_order_runs(docs: dict, duration: float, seed: int, commands: list) -> dict:
    """setting → N → the documents of both RLS predictors at order N: the tables' runs where a
    predictor's own order is N, new runs (``--set predictor_settings.order=N``) where not."""
    out = {}
    for setting, (preset, _) in RUNS.items():
        out[setting] = {}
        for n in ORDERS:
            have = [d for d in docs[setting] if d.get("predictor") in RLS and order_of(d) == n]
            missing = [p for p in RLS if p not in {d["predictor"] for d in have}]
            if missing:
                new, command = compare(preset, missing, duration, seed,
                                       (f"predictor_settings.order={n}",))
                commands.append(" ".join(command))
                if any(order_of(d) != n for d in new):
                    raise RuntimeError(f"{preset}: a run did not take order {n}")
                have += new
            out[setting][n] = have
    return out


def equal_order_table(runs: dict, paper_docs: dict, data: dict) -> str:
    """Both RLS predictors at each equal order N (RMS error, generalized ÷ one-step) and, per
    setting, the ratio at the paper's orders; fills ``data`` with the cells and the finding."""
    paper_n = {p: settings_for(p).order for p in RLS}
    rows, cells, leads, paper_ratios = [], [], [], []
    for setting, by_n in runs.items():
        first = True
        for n, docs in by_n.items():
            one, gen = ([ours(docs, p, c, "rms_error_mm") for c in COLUMNS] for p in RLS)
            ratio = [g / o for g, o in zip(gen, one, strict=True)]
            for c, o, g, r in zip(COLUMNS, one, gen, ratio, strict=True):
                cells.append({"setting": setting, "order": n, "scenario": c,
                              "one_step": o, "generalized": g, "ratio": r})
                leads.append((n, r))
            rows += [[setting if first else "", f"{n}", "`one-step`",
                      *[R.fmt(v, 3) for v in one]],
                     ["", "", "`generalized`", *[R.fmt(v, 3) for v in gen]],
                     ["", "", "÷", *[f"**{R.fmt(v, 3)}**" for v in ratio]]]
            first = False
        gen_p, one_p = ([ours(paper_docs[setting], p, c, "rms_error_mm") for c in COLUMNS]
                        for p in ("generalized", "one-step"))
        ratio = [g / o for g, o in zip(gen_p, one_p, strict=True)]
        paper_ratios += ratio
        rows.append(["", f"{paper_n['generalized']} ÷ {paper_n['one-step']}",
                     "÷ at the paper's orders", *[R.fmt(v, 3) for v in ratio]])
    ahead = [100.0 * (1.0 - r) for _, r in leads if r < 1.0]
    behind = [100.0 * (r - 1.0) for _, r in leads if r >= 1.0]
    per_n = ", ".join(f"N = {n}: {sum(r < 1.0 for m, r in leads if m == n)}/"
                      f"{sum(m == n for m, _ in leads)}" for n in ORDERS)
    line = (f"Generalized ahead of one-step at equal order: {len(ahead)}/{len(leads)} cells "
            f"({per_n})")
    if ahead:
        line += f", by {R.fmt(min(ahead), 2)}–{R.fmt(max(ahead), 2)} %"
    if behind:
        line += (f"; behind in {len(behind)}, by {R.fmt(min(behind), 2)}–"
                 f"{R.fmt(max(behind), 2)} %")
    k = sum(r < 1.0 for r in paper_ratios)
    line += (f". At the paper's orders (generalized N = {paper_n['generalized']}, one-step "
             f"N = {paper_n['one-step']}) it is ahead in {k}/{len(paper_ratios)}: generalized ÷ "
             f"one-step {R.fmt(min(paper_ratios), 3)}–{R.fmt(max(paper_ratios), 3)}.")
    forecast = {}
    for n in ORDERS:
        for p in RLS:
            values = [d["prediction_rms_mm"]["lead_N"] for by_n in runs.values()
                      for d in by_n[n] if d.get("predictor") == p and "prediction_rms_mm" in d]
            forecast[f"{p} N={n}"] = float(np.sqrt(np.mean(np.square(values))))
    line += " 25-ms forecast error (RMS over the columns): " + "; ".join(
        f"N = {n}: generalized {R.fmt(forecast[f'generalized N={n}'], 3)} mm, one-step "
        f"{R.fmt(forecast[f'one-step N={n}'], 3)} mm" for n in ORDERS) + "."
    data.update({"orders": list(ORDERS), "paper_orders": paper_n, "cells": cells,
                 "paper_order_ratios": paper_ratios, "forecast_lead_N_mm": forecast,
                 "finding": line})
    return (R.table(["setting", "N", "predictor", *[SHORT[c] for c in COLUMNS]], rows)
            + "\n\n" + line)


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
    equal = equal_order_runs(docs, duration, a.seed, commands)
    cells: list = []
    tables = tables_of(docs, cells)
    equal_data: dict = {}
    tables["equal-order|Generalized against one-step at equal order N: RMS position error [mm], "
           "both presets, the tables' seed and duration"] = equal_order_table(equal, docs,
                                                                            equal_data)
    lines = [f"{setting}: {line}" for setting in RUNS
             for line in findings(docs[setting], setting, COLUMNS)
             if "not measured here" not in line]
    lines.append("both: " + hardware_effort_finding(docs["simulation"], docs["hardware"],
                                                    COLUMNS))
    R.write("tuna_tables", "Tuna et al. 2013 Tables I–III", {
        "command": " ; ".join(commands), "duration_s": duration, "seed": a.seed,
        "cells": cells, "findings": lines, "equal_order": equal_data}, tables, a.quick,
        notes="Ours: the physical sonomicrometer with its white range error, causal delivery, "
              "the error scored against the recorded stream as in the paper. Table I beside "
              "the simulation preset, Tables II–III beside the hardware preset; a simulation is "
              "never set against a hardware table. The findings, as `rhmpc compare --paper` "
              "prints them:\n\n```text\n" + "\n".join(lines) + "\n```")


if __name__ == "__main__":
    main()
