"""The learned and multi-point predictors on a real recording, beside the adaptive ones.

The literature's protocol on the shipped ``hamlyn-phantom`` recording (four points tracked at
25 frames/s in stereo video of a beating-heart phantom; point 4, the papers' point of
interest): the fitted predictors fitted on the frames before 600, every other one running
causally from frame 0, the forecasts issued in frames [600, 700) scored 1 … 4 frames ahead
(3-D RMS in mm) — ``rhmpc predict --data hamlyn-phantom --split 600:700 --leads 4`` with
``--seed`` 0, 1 and 2: the table gives the mean over the seeds and, for the networks whose
training draws at random, the range. Beside it, the anchors the papers publish on the same
protocol, and the closed loop on the same recording (``rhmpc simulate --data hamlyn-phantom
--poi 4``, 30 s, the fitted predictors fitted on the settling window). Quick: seed 0 and no
networks.

    python benchmarks/learned_table.py [--quick]
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import _results as R
import numpy as np

from predictors import LEARNED, needs_torch
from predictors.registry import default_predictors, torch_available
from rhmpc.cli import main as rhmpc

DATA, POI, SPLIT, LEADS = "hamlyn-phantom", 4, "600:700", 4
SEEDS = (0, 1, 2)
CLOSED_LOOP = ("exact", "hold", "one-step", "generalized", "st-rls", "st-ridge", "combination")
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


def closed_loop(name: str, folder: Path) -> dict:
    """``rhmpc simulate`` on the shipped recording with ``name``: the summary's figures."""
    out = folder / f"simulate-{name}.json"
    rhmpc(["simulate", "--data", DATA, "--poi", str(POI), "--predictor", name,
           "--duration", "30", "--seed", "0", "--out", str(out)])
    doc = json.loads(out.read_text())
    return {"predictor": name, "rms_error_mm": doc["rms_error_mm"],
            "rms_error_axis_mm": doc["rms_error_axis_mm"], "max_error_mm": doc["max_error_mm"],
            "settling_s": doc["settling_s"]}


def interpolation_floor(settling_s: float) -> list[float]:
    """RMS [mm] per axis, x y z, of the reference's piecewise-quadratic interpolation of the
    recording's own frames (a perfect forecast at every frame) against the recording's linear
    interpolant, the truth a closed loop on a recording is scored against, at 0.5 ms steps
    after ``settling_s`` (:func:`rhmpc.control.reference.quadratic_weights`)."""
    from rhmpc.control.reference import quadratic_weights
    from sim.recordings import load_points
    from sim.recordings.shipped import resolve

    path, read, _ = resolve(DATA, {})
    rec = load_points(path, **read)[POI - 1]
    z = 1e3 * rec.z[round(settling_s / rec.period):]
    s = np.arange(0.0, z.shape[0] - 2, 0.5e-3 / rec.period)
    m, w = quadratic_weights(s, z.shape[0])
    quadratic = sum(w[:, [j]] * z[m + j] for j in range(3))
    linear = np.stack([np.interp(s, np.arange(z.shape[0]), z[:, k]) for k in range(3)], 1)
    return np.sqrt(np.mean((quadratic - linear) ** 2, axis=0)).tolist()


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
    a = ap.parse_args()
    online = [n for n in default_predictors(fitted=True) if n not in LEARNED]
    names = [*online[:-1], *LEARNED, online[-1]]  # every fitted one, the GRUs included
    if a.quick or not torch_available():
        names = [n for n in names if not needs_torch(n)]
    seeds = SEEDS[:1] if a.quick else SEEDS
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        table = summarise([open_loop(seed, names, folder) for seed in seeds])
        loop = [closed_loop(name, folder) for name in CLOSED_LOOP]
    floor = interpolation_floor(loop[0]["settling_s"])
    rows = [[f"`{n}`", d["family"], *(lead_cell(d, k, needs_torch(n)) for k in range(LEADS)),
             R.fmt(d["update_us"]), "—" if d["fit_s"] is None else R.fmt(d["fit_s"], 1)]
            for n, d in table.items()]
    lead_head = [f"{k} ({40 * k} ms)" for k in range(1, LEADS + 1)]
    tab = R.table(["predictor", "family", *lead_head, "update + forecast [µs]", "fit [s]"], rows)
    about = {2: "≈ ", 3: ""}
    lit = R.table(["source", "model", "phantom", "in vivo"],
                  [[s, m, about[n] + R.fmt(ph, n), about[n] + R.fmt(iv, n)]
                   for s, m, ph, iv, n in LITERATURE])
    cl = R.table(["predictor", "RMS error [mm]", "RMS x / y / z [mm]", "max error [mm]"],
                 [[f"`{d['predictor']}`", R.fmt(d["rms_error_mm"]),
                   " / ".join(R.fmt(v) for v in d["rms_error_axis_mm"]), R.fmt(d["max_error_mm"])]
                  for d in loop]
                 + [["quadratic reference through the true frames, against the recording's "
                     "linear interpolant", R.fmt(float(np.sqrt(np.sum(np.square(floor))))),
                     " / ".join(R.fmt(v) for v in floor), "—"]])
    R.write("learned_table", "Learned and multi-point predictors on the phantom recording", {
        "data": DATA, "poi": POI, "split": SPLIT, "leads": LEADS, "seeds": list(seeds),
        "open_loop": table, "closed_loop": loop, "interpolation_floor_axis_mm": floor,
        "literature": [{"source": s, "model": m, "phantom_rms_mm": ph, "invivo_rms_mm": iv}
                       for s, m, ph, iv, _ in LITERATURE]},
        {"open|Forecast RMS [mm] at each lead [frames]: mean over the seeds (range)": tab,
         "literature|Published on the same protocol, 1 frame (40 ms) ahead [mm]": lit,
         "closed|Closed loop, 30 s (scored after the settling window)": cl}, a.quick,
        notes=f"`rhmpc predict --data {DATA} --poi {POI} --split {SPLIT} --leads {LEADS} "
              "--seed S`; update + forecast: the mean time of one update with its forecast, "
              "one core; fit: seed 0's fitting time.")


if __name__ == "__main__":
    main()
