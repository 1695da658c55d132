"""Yuen et al. 2008 Fig. 3A beside ours: ``rhmpc predict --study noise`` (and ``hr-step``).

Yuen's Fig. 3A is a plot, not a table; what it states in its text is the comparison made here:
the EKF predicts best, the filters do better than the measurement noise σ_R, and last cycle's
error equals σ_R. For each σ_R the table gives every predictor's mean RMS one-sample-ahead error
(28 Hz, mitral-1d), which predictor is best, and last cycle's error over σ_R.

    python benchmarks/yuen_noise.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys

import _results as R


def study(name: str, trials: int) -> dict:
    cmd = [sys.executable, "-m", "rhmpc.cli", "predict", "--study", name, "--trials", str(trials),
           "--seed", "5", "--jobs", "1", "--json"]
    doc = json.loads(subprocess.run(cmd, check=True, capture_output=True, text=True).stdout)
    doc["command"] = " ".join(["rhmpc", *cmd[3:]])
    return doc


def grid(doc: dict, label: str, extra) -> str:
    names = doc["settings"]["predictors"]
    cells = {(r["parameter"], r["predictor"]): r["rms_mm"] for r in doc["rows"]}
    rows = []
    for p in doc["parameters"]:
        vals = {n: cells[(p, n)] for n in names}
        best = min(vals, key=vals.get)
        rows.append([R.fmt(p, 1), *[("**" + R.fmt(vals[n]) + "**") if n == best else
                                    R.fmt(vals[n]) for n in names], f"`{best}`",
                     *extra(p, vals)])
    return rows, names


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="5 trials per cell instead of 20")
    a = ap.parse_args()
    trials = 5 if a.quick else 20
    noise, step = study("noise", trials), study("hr-step", trials)
    for doc in (noise, step):
        for r in doc["rows"]:
            r["ratio_to_sigma"] = None
    for r in noise["rows"]:
        r["ratio_to_sigma"] = r["rms_mm"] / r["parameter"]
    rows, names = grid(noise, "σ_R", lambda p, v: [R.fmt(v["last-cycle"] / p, 2)])
    t1 = R.table(["σ_R [mm]", *[f"`{n}`" for n in names], "best", "last cycle ÷ σ_R"], rows)
    rows, names = grid(step, "ΔHR", lambda p, v: [])
    t2 = R.table(["ΔHR [bpm]", *[f"`{n}`" for n in names], "best"], rows)
    R.write("yuen_noise", "Yuen et al. 2008 §III-D studies", {
        "trials": trials, "noise": noise, "hr_step": step},
        {"Noise study (Fig. 3A): mean RMS one-sample-ahead error [mm]": t1,
         "Heart-rate step (Fig. 3B), σ_R = 1.3 mm: mean RMS one-sample-ahead error [mm]": t2},
        a.quick,
        notes="Yuen et al. report, from 100 trials: the EKF best, the filters below σ_R, last "
              "cycle equal to σ_R (Fig. 3A); the EKF best after a step in heart rate (Fig. 3B).")


if __name__ == "__main__":
    main()
