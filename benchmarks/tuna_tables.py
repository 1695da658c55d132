"""Tuna et al. 2013 Tables I–III beside ours, and their findings, from the README's commands.

The tables and the verdicts are those of exactly the README's two commands, run here with
``--json``: ``rhmpc compare --preset tuna2013 --paper`` (Table I, their simulation: the MPC's
linear model as the plant) and ``rhmpc compare --preset tuna2013-hardware --paper`` (Tables
II–III, their hardware: the hardware-like PHANToM, the error from the encoders' forward
kinematics), at their default seeds, duration and settling. Then:

- the same two commands on two disjoint sets of five seeds, half of Tuna's ten runs each
  (``--seed 0 --seeds 5`` and ``--seed 5 --seeds 5``): each finding's verdict from both sets,
  side by side, and the verdicts on the first n seeds of each (n = 2 … 5): how many seeds decide
  them; the seed-to-seed spread of the cells;
- hardware effort above simulation effort, paired by seed across the two presets;
- the two RLS predictors at equal order (both at N = 16, both at N = 10; Tuna ran one-step at
  16 and generalized at 10, §VIII-B) on the first set's seeds;
- the time of the README's two commands on this machine: wall time, the CPU time of every
  process, that CPU time in gain ticks g, and the wall time it projects on two idle cores.

Writes ``docs/results/tuna_tables``. ``--reuse DIR`` keeps each command's JSON in DIR and reads
it back on the next call (the timing is then the first call's).

    python benchmarks/tuna_tables.py [--quick] [--reuse DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shlex
import subprocess
import sys
import time
from pathlib import Path

import _results as R
import numpy as np

from rhmpc.cli.compare import PAPER_SEEDS
from rhmpc.paper.findings import cross_finding, findings
from rhmpc.paper.tables import COLUMNS, SETTING, TUNA2013, cell
from rhmpc.predictors import settings_for

#: The README's command of each setting.
PRESETS = {"simulation": "tuna2013", "hardware": "tuna2013-hardware"}
METRICS = {"rms_error_mm": ("RMS position error [mm]", 3),
           "max_error_mm": ("maximum error [mm]", 3),
           "rms_effort_mNm": ("RMS control effort [mN·m]", 1)}
TITLES = {"I": "Table I (simulation)", "II": "Table II (hardware experiments)",
          "III": "Table III (hardware experiments, EKF)"}
SHORT = {"fixed-a1-top": "fixed a1", "fixed-a2-top": "fixed a2", "varying-a1-top": "var. a1",
         "varying-a3-top": "var. a3", "varying-a1-side": "var. a1 side",
         "varying-a3-side": "var. a3 side"}
#: Seeds of each of the two disjoint sets the verdicts are compared on: half of Tuna's ten runs.
SET_SEEDS = 5
#: The equal-order comparison: the two RLS predictors, both at each of these orders N.
RLS = ("one-step", "generalized")
ORDERS = (16, 10)


def readme_command(preset: str) -> list[str]:
    """The README's command of ``preset``, as a user types it."""
    return ["rhmpc", "compare", "--preset", preset, "--paper"]


def compare(args: list[str], reuse: Path | None) -> tuple[dict, dict]:
    """``rhmpc compare ARGS --json``: its document, and its wall and CPU time [s] (every
    process's: the command's and its workers')."""
    cache = None
    if reuse is not None:
        # the README's command runs the default seeds: they belong to its key
        words = [*args, f"default-seeds-{PAPER_SEEDS}"]
        cache = reuse / ("_".join(a.lstrip("-").replace("=", "-") for a in words) + ".json")
        if cache.is_file():
            saved = json.loads(cache.read_text())
            return saved["doc"], saved["timing"]
    cmd = [sys.executable, "-m", "rhmpc.cli", *args[1:], "--json", "--quiet"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    timing = {"wall_s": wall, "cpu_s": cpu, "load_average": os.getloadavg()[0]}
    doc = json.loads(out)
    if cache is not None:
        reuse.mkdir(parents=True, exist_ok=True)
        cache.write_text(json.dumps({"doc": doc, "timing": timing}))
    return doc, timing


def paper_tables(runs: dict[str, list[dict]], cells: list) -> dict[str, str]:
    """Every published table beside the README's runs of its own setting: paper, ours (mean ±
    half-width of the 95 % interval), ours ÷ paper."""
    out = {}
    for (tab, metric), published in TUNA2013.items():
        docs = runs[SETTING[tab]]
        label, digits = METRICS[metric]
        rows = []
        for pred, paper_cells in published.items():
            paper_row, ours_row, ratio_row = [f"`{pred}`", "paper"], ["", "ours"], ["", "÷"]
            for col in COLUMNS:
                paper, mine = paper_cells[col], cell(docs, pred, col, metric)
                low, high = mine["ci95"]
                cells.append({"table": tab, "metric": metric, "predictor": pred,
                              "scenario": col, "paper": paper, **mine,
                              "ratio": mine["mean"] / paper})
                paper_row.append(R.fmt(paper, digits))
                ours_row.append(f"**{R.fmt(mine['mean'], digits)}** ± "
                                f"{R.fmt((high - low) / 2, digits)}")
                ratio_row.append(R.fmt(mine["mean"] / paper, 2))
            rows += [paper_row, ours_row, ratio_row]
        out[f"{TITLES[tab]}: {label}"] = R.table(
            ["predictor", "", *[SHORT[c] for c in COLUMNS]], rows)
    return out


def _counts(f) -> str:
    return f"{f.count('holds')} / {f.count('fails')} / {f.count('undecided')}"


def verdict_table(sets: dict[str, dict[str, list[dict]]], data: dict) -> str:
    """Each finding's verdict on each set of seeds (columns holding / failing / undecided)."""
    names = list(sets)
    judged = {name: {s: findings(docs, s) for s, docs in runs.items()}
              for name, runs in sets.items()}
    rows, out = [], []
    for setting in PRESETS:
        for k, f in enumerate(judged[names[0]][setting]):
            others = [judged[n][setting][k] for n in names[1:]]
            rows.append([setting, f.relation.title, f.published,
                         *[f"{g.verdict} ({_counts(g)})" for g in (f, *others)]])
            out.append({"setting": setting, **f.to_dict(),
                        "other_seeds": [{"seeds": n, **g.to_dict()}
                                        for n, g in zip(names[1:], others, strict=True)]})
    cross = [cross_finding(runs["simulation"], runs["hardware"]) for runs in sets.values()]
    rows.append(["both", cross[0].relation.title, cross[0].published,
                 *[f"{g.verdict} ({_counts(g)})" for g in cross]])
    out.append({"setting": "both", **cross[0].to_dict(),
                "other_seeds": [{"seeds": n, **g.to_dict()}
                                for n, g in zip(names[1:], cross[1:], strict=True)]})
    data["findings"] = out
    data["agree"] = all(f["verdict"] == g["verdict"] for f in out for g in f["other_seeds"])
    return R.table(["setting", "finding", "published",
                    *[f"seeds {n}: verdict (columns holding / failing / undecided)"
                      for n in names]], rows)


def seeds_needed(sets: dict[str, dict[str, list[dict]]], count: int, data: dict) -> str:
    """The verdicts on the first n seeds of each set, n = 2 … ``count``."""
    rows, agree = [], {}
    first = {name: {s: sorted({d["seed"] for d in docs}) for s, docs in runs.items()}
             for name, runs in sets.items()}
    for setting in PRESETS:
        per_n = {}
        for n in range(2, count + 1):
            per_n[n] = []
            for name, runs in sets.items():
                keep = set(first[name][setting][:n])
                per_n[n].append(findings([d for d in runs[setting] if d["seed"] in keep],
                                         setting))
        for k, f in enumerate(per_n[count][0]):
            verdicts = {n: [fs[k].verdict for fs in per_n[n]] for n in per_n}
            rows.append([setting, f.relation.title,
                         *[" / ".join(v) for v in verdicts.values()]])
            for n, v in verdicts.items():
                agree.setdefault(n, []).append(len(set(v)) == 1)
    data["agree_by_seeds"] = {str(n): f"{sum(v)}/{len(v)}" for n, v in agree.items()}
    rows.append(["", "findings with the same verdict on both sets",
                 *[f"{sum(v)}/{len(v)}" for v in agree.values()]])
    return R.table(["setting", "finding",
                    *[f"{n} seeds ({' / '.join(sets)})" for n in range(2, count + 1)]], rows)


def spread_table(runs: dict[str, list[dict]], data: dict) -> str:
    """Seed-to-seed spread of each metric (standard deviation ÷ mean over a cell's seeds),
    median and largest over the cells of each setting."""
    rows, out = [], {}
    for setting, docs in runs.items():
        for metric, (label, _) in METRICS.items():
            rel = []
            for pred in {d["predictor"] for d in docs}:
                for col in COLUMNS:
                    v = [d[metric] for d in docs if d["predictor"] == pred
                         and d["scenario"] == col and "error" not in d]
                    if len(v) > 1:
                        rel.append(100.0 * np.std(v, ddof=1) / np.mean(v))
            out[f"{setting} {metric}"] = {"median_pct": float(np.median(rel)),
                                          "max_pct": float(np.max(rel))}
            rows.append([setting, label, R.fmt(float(np.median(rel)), 1),
                         R.fmt(float(np.max(rel)), 1)])
    data["spread"] = out
    return R.table(["setting", "metric", "median over cells [%]", "largest [%]"], rows)


def timing_table(timings: dict[str, dict], runs: dict[str, list[dict]], g_us: float,
                 data: dict) -> str:
    """The README's two commands: runs, wall, CPU, CPU in g, per simulated second, projected
    on two idle cores."""
    rows, total_cpu = [], 0.0
    out = {}
    for setting, t in timings.items():
        docs = [d for d in runs[setting] if "error" not in d]
        simulated = sum(d["settings"]["loop"]["duration"] for d in docs)
        cpu_g = t["cpu_s"] / (g_us * 1e-6)
        total_cpu += t["cpu_s"]
        out[setting] = {**t, "runs": len(runs[setting]), "simulated_s": simulated,
                        "cpu_g": cpu_g, "cpu_per_simulated_s_g": cpu_g / simulated,
                        "two_cores_s": t["cpu_s"] / 2}
        rows.append([f"`{' '.join(readme_command(PRESETS[setting]))}`",
                     R.fmt(len(runs[setting])), R.fmt(t["wall_s"], 0), R.fmt(t["cpu_s"], 0),
                     R.fmt(cpu_g, 2, sci=True), R.fmt(cpu_g / simulated, 0),
                     R.fmt(t["cpu_s"] / 2, 0), R.fmt(t["load_average"], 2)])
    both = {"cpu_s": total_cpu, "two_cores_s": total_cpu / 2,
            "wall_s": sum(t["wall_s"] for t in timings.values())}
    out["both"] = both
    rows.append(["both", "", R.fmt(both["wall_s"], 0), R.fmt(total_cpu, 0),
                 R.fmt(total_cpu / (g_us * 1e-6), 2, sci=True), "",
                 R.fmt(both["two_cores_s"], 0), ""])
    data["timing"] = out
    return R.table(["command", "runs", "wall [s]", "CPU [s]", "CPU [g]",
                    "CPU per simulated s [g]", "on two idle cores [s]", "load average"], rows)


def order_of(doc: dict) -> int:
    """The order N that an RLS predictor's run ran with (its settings over the defaults)."""
    return settings_for(doc["predictor"], **doc["settings"].get("predictor_settings", {})).order


def equal_order_runs(runs: dict, seeds: int, extra: list[str], reuse) -> dict:
    """setting → N → the documents of both RLS predictors at order N: the README's runs where
    a predictor's own order is N, new runs (``--set predictor_settings.order=N``) where not."""
    out = {}
    for setting, preset in PRESETS.items():
        out[setting] = {}
        for n in ORDERS:
            have = [d for d in runs[setting] if d.get("predictor") in RLS and order_of(d) == n]
            missing = [p for p in RLS if p not in {d["predictor"] for d in have}]
            if missing:
                new, _ = compare(["rhmpc", "compare", "--preset", preset, "--predictors",
                                  ",".join(missing), "--seeds", str(seeds), *extra, "--set",
                                  f"predictor_settings.order={n}"], reuse)
                if any(order_of(d) != n for d in new["runs"]):
                    raise RuntimeError(f"{preset}: a run did not take order {n}")
                have += new["runs"]
            out[setting][n] = have
    return out


def equal_order_table(runs: dict, paper_runs: dict, data: dict) -> str:
    """Both RLS predictors at each equal order N (mean RMS error over the seeds, generalized ÷
    one-step) and, per setting, the ratio at the paper's orders; fills ``data``."""
    paper_n = {p: settings_for(p).order for p in RLS}
    rows, cells, leads, paper_ratios = [], [], [], []
    for setting, by_n in runs.items():
        first = True
        for n, docs in by_n.items():
            one, gen = ([cell(docs, p, c, "rms_error_mm")["mean"] for c in COLUMNS]
                        for p in RLS)
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
        gen_p, one_p = ([cell(paper_runs[setting], p, c, "rms_error_mm")["mean"]
                         for c in COLUMNS] for p in ("generalized", "one-step"))
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
    line += " 25-ms forecast error (RMS over the runs): " + "; ".join(
        f"N = {n}: generalized {R.fmt(forecast[f'generalized N={n}'], 3)} mm, one-step "
        f"{R.fmt(forecast[f'one-step N={n}'], 3)} mm" for n in ORDERS) + "."
    data.update({"orders": list(ORDERS), "paper_orders": paper_n, "cells": cells,
                 "paper_order_ratios": paper_ratios, "forecast_lead_N_mm": forecast,
                 "finding": line})
    return (R.table(["setting", "N", "predictor", *[SHORT[c] for c in COLUMNS]], rows)
            + "\n\n" + line)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true",
                    help="12-s runs, 2 seeds, sets of 2 instead of the README's defaults")
    ap.add_argument("--reuse", type=Path, metavar="DIR",
                    help="keep each command's JSON in DIR and read it back when present")
    a = ap.parse_args()
    size = 2 if a.quick else SET_SEEDS
    extra = ["--duration", "12", "--seeds", "2"] if a.quick else []
    runs, timings, commands = {}, {}, []
    sets: dict[str, dict[str, list[dict]]] = {f"{k}–{k + size - 1}": {} for k in (0, size)}
    for setting, preset in PRESETS.items():
        command = readme_command(preset) + extra
        doc, timings[setting] = compare(command, a.reuse)
        runs[setting] = doc["runs"]
        commands.append(shlex.join(command))
        for first, name in zip((0, size), sets, strict=True):
            doc, _ = compare([*command[:5], *extra[:2], "--seed", str(first), "--seeds",
                              str(size)], a.reuse)
            sets[name][setting] = doc["runs"]
    first_set = next(iter(sets.values()))
    data: dict = {"commands": commands, "seeds": sorted({d["seed"] for d in runs["hardware"]}),
                  "sets": list(sets)}
    cells: list = []
    tables = paper_tables(runs, cells)
    tables["verdicts|Each finding on two disjoint sets of five seeds (columns holding / failing "
           "/ undecided)"] = verdict_table(sets, data)
    tables["seeds|The verdicts on the first n seeds of each set"] = seeds_needed(sets, size,
                                                                                  data)
    tables["spread|Seed-to-seed spread of a cell (standard deviation ÷ mean), the first set"] = \
        spread_table(first_set, data)
    g_us = R.yardstick()["gain_tick_us"]
    tables["timing|The README's two commands on this machine"] = timing_table(
        timings, runs, g_us, data)
    equal_data: dict = {}
    equal = equal_order_runs(first_set, size, extra[:2], a.reuse)
    tables["equal-order|Generalized against one-step at equal order N: mean RMS position "
           "error [mm], both presets, the first set's seeds"] = equal_order_table(
        equal, first_set, equal_data)
    lines = [f"{setting}: {f.line()}" for setting in PRESETS
             for f in findings(runs[setting], setting)]
    lines.append("both: " + cross_finding(runs["simulation"], runs["hardware"]).line())
    data.update({"cells": cells, "equal_order": equal_data, "lines": lines})
    R.write("tuna_tables", "Tuna et al. 2013 Tables I–III", data, tables, a.quick,
            notes="Ours: the README's commands (" + "; ".join(f"`{c}`" for c in commands) +
            "), the physical sonomicrometer with its white range error, causal delivery, "
            "the error scored against the recorded stream as in the paper. Table I beside "
            "the simulation preset, Tables II–III beside the hardware preset; a simulation is "
            "never set against a hardware table. The findings, as the README's commands "
            "print them (the cross-preset one from both commands' runs):\n\n```text\n"
            + "\n".join(lines) + "\n```")


if __name__ == "__main__":
    main()
