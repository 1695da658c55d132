"""
The safety envelope: a plane the tool may not cross
===================================================

A Cartesian half-space in front of the tissue: the tool may go at most ``cartesian_depth`` past
the plane ``cartesian_point``/``cartesian_normal`` (relative to the mean POI). The heart moves
through the plane; the tool follows it up to the plane and stops there. On the ticks where the
plane binds, OSQP (level 3 of the screening cascade) needs hundreds of iterations: this study lets
it run to convergence (``mpc.max_iter = 4000``); the real-time bound, 10, takes the fallbacks
there (the plane holds, the tracking stops).
"""

import matplotlib.pyplot as plt
import numpy as np

from rhmpc.experiment import RunConfig, run_experiment

base = RunConfig(predictor="exact", scenario="fixed-a2-top", sensor="ideal", seed=0).replace(
    **{"loop.duration": 4.0, "loop.settling": 1.0})
plane = {"mpc.cartesian": "halfspace", "mpc.cartesian_point": [0.001, 0.0, 0.0],
         "mpc.cartesian_normal": [1.0, 0.0, 0.0], "mpc.cartesian_depth": 0.0005,
         "mpc.max_iter": 4000}
free, _ = run_experiment(base)
fenced, doc = run_experiment(base.replace(**plane))
print("fallbacks", doc["fallbacks"])

# %%
# The x coordinate of the POI and of the tool, relative to the mean POI.
center = np.nanmean(free.poi[:, 0])
fig, ax = plt.subplots(figsize=(8, 4), constrained_layout=True)
ax.plot(free.time, 1e3 * (free.ee[:, 0] - center), lw=2.5, alpha=0.5, label="tool, no envelope")
ax.plot(fenced.time, 1e3 * (fenced.ee[:, 0] - center), lw=1.2, label="tool, half-space")
ax.plot(free.time, 1e3 * (free.poi[:, 0] - center), "k:", lw=1.0, label="POI")
ax.axhline(1.0, color="C3", ls="--", lw=0.8, label="plane")
ax.axhline(1.5, color="C3", ls=":", lw=0.8, label="plane + depth")
ax.set(xlabel="time [s]", ylabel="x [mm]", title="a half-space envelope in front of the tissue")
ax.legend(fontsize=8, ncol=3, loc="lower left")
plt.show()
