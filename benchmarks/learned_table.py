"""The learned and multi-point predictors on a real recording, beside the adaptive ones.

The literature's protocol on the shipped ``hamlyn-phantom`` recording (four points tracked at
25 frames/s in stereo video of a beating-heart phantom; point 4, the papers' point of
interest): the fitted predictors fitted on the frames before 600, every other one running
causally from frame 0, the forecasts issued in frames [600, 700) scored 1 … 4 frames ahead
(3-D RMS in mm) — ``rhmpc predict --data hamlyn-phantom --split 600:700 --leads 4`` with
``--seed`` 0, 1 and 2: the table gives the mean over the seeds and, for the networks whose
training draws at random, the range. Beside it, the anchors the papers publish on the same
protocol, and the closed loop on the same recording with the same split (``rhmpc compare
--data hamlyn-phantom --poi 4 --split 600:750``): each predictor scored at the instants of the
frames 600 … 749, beside its open-loop forecast of the same frames one frame ahead. Quick:
seed 0 and no networks.

    python benchmarks/learned_table.py [--quick] [--closed-loop]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import _results as R
import numpy as np

from rhmpc.cli import main as rhmpc
from rhmpc.predictors import LEARNED, needs_torch
from rhmpc.predictors.registry import default_predictors, torch_available

DATA, POI, SPLIT, LEADS = "hamlyn-phantom", 4, "600:700", 4
SEEDS = (0, 1, 2)
CLOSED_LOOP = ("exact", "hold", "one-step", "generalized", "st-rls", "st-ridge", "combination")
#: The closed loop's split: the loop from frame 0, the fitted predictors fitted on the frames
#: before 600, the score on the instants of frames 600 … 749 (the recording's end).
CLOSED_SPLIT = "600:750"
#: 3-D RMS forecast error at 1 frame (40 ms) on the point of interest [mm], as published on
#: the phantom recording and on the same group's in-vivo recording (not shipped): Zhang et al.
#: 2022 (IEEE SPL 29:787, read from its figures), Xu et al. 2026 (CMES 146(1)).
#: (source, model, phantom, in vivo, digits the source gives).
LITERATURE = (("Zhang et al. 2022", "LSTM(300), one step per call", 0.07, 0.32, 2),
              ("Xu et al. 2026", "LSTM (2 × 600)", 0.111, 0.222, 3),
              ("Xu et al. 2026", "TCN (4 blocks, 64 channels)", 0.239, 0.343, 3))


def open_loop(seed: int, names: list[str], folder: Path) -> dict:
    """``rhmpc predict`` on the shipped recording with ``seed``: {name: row dicts by lead}."""
    out = folder / f"predict-{seed}.json"
    rhmpc(["predict", "--data", DATA, "--poi", str(POI), "--split", SPLIT, "--leads", str(LEADS),
           "--predictors", ",".join(names), "--seed", str(seed), "--out", str(out)])
    doc = json.loads(out.read_text())
    rows: dict[str, dict] = {}
    for r in doc["results"]:
        rows.setdefault(r["predictor"], {"family": r["family"]})[r["lead_samples"]] = r
    return rows


def closed_loop(folder: Path) -> list[dict]:
    """``rhmpc compare --data … --split``: each predictor in closed loop, scored at the measured
    instants of the frames [600, 750), beside its open-loop forecast of the same frames."""
    out = folder / "compare.json"
    rhmpc(["compare", "--data", DATA, "--poi", str(POI), "--split", CLOSED_SPLIT,
           "--predictors", ",".join(CLOSED_LOOP), "--seed", "0", "--quiet", "--out", str(out)])
    return json.loads(out.read_text())["loop_gap"]


def summarise(runs: list[dict]) -> dict:
    """Per predictor: family, mean RMS [mm] per lead over the seeds, its range, the time of
    one update with its forecast [µs] and of the fit [s] (seed 0)."""
    out = {}
    for name, first in runs[0].items():
        rms = np.array([[run[name][k]["rms_error_mm"] for k in range(1, LEADS + 1)]
                        for run in runs])
        out[name] = {"family": first["family"], "rms_mm": rms.mean(axis=0).tolist(),
                     "rms_min_mm": rms.min(axis=0).tolist(),
                     "rms_max_mm": rms.max(axis=0).tolist(),
                     "update_us": first[1].get("update_us"), "fit_s": first[1].get("fit_s")}
    return out


def lead_cell(d: dict, k: int, spread: bool) -> str:
    cell = R.fmt(d["rms_mm"][k], 3)
    if spread and d["rms_max_mm"][k] > d["rms_min_mm"][k]:
        cell += f" ({R.fmt(d['rms_min_mm'][k], 3)}–{R.fmt(d['rms_max_mm'][k], 3)})"
    return cell


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="seed 0 only, no networks")
    ap.add_argument("--closed-loop", action="store_true",
                    help="run the closed loop only; the open-loop table and its seeds are read "
                         "back from docs/results/learned_table.json (their runs take an hour)")
    a = ap.parse_args()
    online = [n for n in default_predictors(fitted=True) if n not in LEARNED]
    names = [*online[:-1], *LEARNED, online[-1]]  # every fitted one, the GRUs included
    if a.quick or not torch_available():
        names = [n for n in names if not needs_torch(n)]
    seeds = SEEDS[:1] if a.quick else SEEDS
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        if a.closed_loop:
            kept = json.loads((R.RESULTS / "learned_table.json").read_text())["data"]
            table, seeds = kept["open_loop"], tuple(kept["seeds"])
        else:
            table = summarise([open_loop(seed, names, folder) for seed in seeds])
        loop = closed_loop(folder)
    rows = [[f"`{n}`", d["family"], *(lead_cell(d, k, needs_torch(n)) for k in range(LEADS)),
             R.fmt(d["update_us"]), "—" if d["fit_s"] is None else R.fmt(d["fit_s"], 1)]
            for n, d in table.items()]
    lead_head = [f"{k} ({40 * k} ms)" for k in range(1, LEADS + 1)]
    tab = R.table(["predictor", "family", *lead_head, "update + forecast [µs]", "fit [s]"], rows)
    about = {2: "≈ ", 3: ""}
    lit = R.table(["source", "model", "phantom", "in vivo"],
                  [[s, m, about[n] + R.fmt(ph, n), about[n] + R.fmt(iv, n)]
                   for s, m, ph, iv, n in LITERATURE])
    cl = R.table(["predictor", "closed loop at the measured instants [mm]",
                  "open loop, 1 frame ahead [mm]", "closed / open",
                  "every tick, against the line between frames [mm]"],
                 [[f"`{r['predictor']}`", R.fmt(r["closed_rms_mm"]),
                   "—" if r["open_rms_mm"] is None else R.fmt(r["open_rms_mm"]),
                   "—" if r["closed_to_open"] is None else R.fmt(r["closed_to_open"], 2),
                   R.fmt(r["interpolated_rms_mm"])] for r in loop])
    R.write("learned_table", "Learned and multi-point predictors on the phantom recording", {
        "data": DATA, "poi": POI, "split": SPLIT, "leads": LEADS, "seeds": list(seeds),
        "open_loop": table, "closed_split": CLOSED_SPLIT, "closed_loop": loop,
        "literature": [{"source": s, "model": m, "phantom_rms_mm": ph, "invivo_rms_mm": iv}
                       for s, m, ph, iv, _ in LITERATURE]},
        {"open|Forecast RMS [mm] at each lead [frames]: mean over the seeds (range)": tab,
         "literature|Published on the same protocol, 1 frame (40 ms) ahead [mm]": lit,
         "closed|Closed loop on the frames 600 … 749, beside the open loop of the same frames":
             cl}, a.quick,
        notes=f"`rhmpc predict --data {DATA} --poi {POI} --split {SPLIT} --leads {LEADS} "
              "--seed S`; update + forecast: the mean time of one update with its forecast, "
              "one core; fit: seed 0's fitting time.")


if __name__ == "__main__":
    main()
