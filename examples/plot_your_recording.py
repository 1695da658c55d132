"""
Every predictor on your own recording
=====================================

``rhmpc predict --data FILE`` runs every predictor open loop on a recording, each at the file's
own rate, and scores its forecasts at several leads against the samples that follow. Here the
"recording" is written first: 40 s of a replica's heart motion seen by a 25-Hz tracker with
0.1 mm of white noise, saved as CSV (seconds and millimetres), exactly as a user's file would be.
"""

import json
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from rhmpc.cli import main
from sim.heart import make_scenario
from sim.recordings.text import save_recording

rng = np.random.default_rng(1)
scenario = make_scenario("fixed-a2-top", rng, duration=40.0)
t = np.arange(0.0, 40.0, 1 / 25)
z = scenario.source.position(t) + 1e-4 * rng.standard_normal((t.size, 3))
folder = Path(tempfile.mkdtemp())
csv = save_recording(folder / "rec25.csv", t, z)
print(csv.read_text().splitlines()[:3])

# %%
# The command, in-process; ``--out`` keeps its JSON document.
out = folder / "leads.json"
main(["predict", "--data", str(csv), "--predictors", "hold,last-cycle,one-step,generalized,ekf,ar",
      "--leads", "4", "--out", str(out)])
doc = json.loads(out.read_text())

# %%
# RMS forecast error against lead, one line per predictor.
fig, ax = plt.subplots(figsize=(7, 4), constrained_layout=True)
for name in doc["predictors"]:
    rows = sorted((1e3 * r["lead_s"], r["rms_error_mm"]) for r in doc["results"]
                  if r["predictor"] == name and r["rms_error_mm"] is not None)
    x, y = zip(*rows, strict=True)
    ax.plot(x, y, "--" if name in ("hold", "last-cycle") else "-", marker="o", label=name)
ax.set(xlabel="lead [ms]", ylabel="RMS forecast error [mm]", yscale="log",
       title="open-loop forecasts on a 25-Hz recording")
ax.legend(ncol=2, fontsize=8)
plt.show()
