"""
Every predictor on your own recording
=====================================

``rhmpc predict --data FILE`` runs the predictors open loop on a recording, each at the file's
own rate, and scores their forecasts at several leads against the samples that follow. Here the
recording is a real one that ships with rhmpc, ``hamlyn-phantom``: four points tracked at 25
frames/s in stereo video of a beating-heart phantom (a MATLAB file, 12 × 750, millimetres). For
your own file, give its path instead, with ``--rate`` and ``--units`` where the file does not
state them (``rhmpc data show FILE`` tells what it reads).
"""

import json
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

from rhmpc.cli import main
from rhmpc.sim.recordings import load_points
from rhmpc.sim.recordings.shipped import resolve

path, read, poi = resolve("hamlyn-phantom", {})
points = load_points(path, **read)
print(f"{Path(path).name}: {len(points)} points, {points[0].t.size} frames at "
      f"{points[0].sample_rate:.0f} Hz; point of interest {poi}")

# %%
# The four points, per axis: the point of interest (4) moves with the others, which is why a
# predictor that reads them (``st-``) can do better than one that reads the POI alone.
fig, axes = plt.subplots(3, 1, figsize=(7, 5), sharex=True, constrained_layout=True)
for k, p in enumerate(points, 1):
    for ax, row in zip(axes, 1e3 * (p.z - p.z.mean(axis=0)).T, strict=True):
        ax.plot(p.t, row, lw=1.4 if k == poi else 0.7, label=f"point {k}")
for ax, name in zip(axes, "xyz", strict=True):
    ax.set_ylabel(f"{name} [mm]")
axes[0].legend(ncol=4, fontsize=8)
axes[-1].set_xlabel("time [s]")
plt.show()

# %%
# The literature's protocol, in-process: the fitted predictors (``ridge``, ``st-ridge``) fit on
# the frames before 600; every other one runs causally from frame 0; the forecasts issued at
# frames 600–699 are scored 1–4 frames ahead. ``--out`` keeps the JSON document. (The neural
# networks, ``lstm``, ``st-gru``, …, need the ``learned`` extra and a few minutes each.)
out = Path(tempfile.mkdtemp()) / "leads.json"
main(["predict", "--data", "hamlyn-phantom", "--split", "600:700", "--leads", "4",
      "--predictors", "hold,one-step,generalized,st-rls,ridge,st-ridge,combination",
      "--out", str(out)])
doc = json.loads(out.read_text())

# %%
# RMS forecast error against lead, one line per predictor, dashed for the baseline.
fig, ax = plt.subplots(figsize=(7, 4), constrained_layout=True)
for name in doc["predictors"]:
    rows = sorted((1e3 * r["lead_s"], r["rms_error_mm"]) for r in doc["results"]
                  if r["predictor"] == name and r["rms_error_mm"] is not None)
    x, y = zip(*rows, strict=True)
    ax.plot(x, y, "--" if name == "hold" else "-", marker="o", label=name)
ax.set(xlabel="lead [ms]", ylabel="RMS forecast error [mm]", yscale="log",
       title="open-loop forecasts of the phantom's point 4 (25 frames/s)")
ax.legend(ncol=2, fontsize=8)
plt.show()
