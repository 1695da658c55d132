"""
A closed-loop tracking run
==========================

The generalized RLS predictor forecasts 25 ms of heart motion from the physical
sonomicrometer's samples; the MPC at 2 kHz tracks that forecast with the PHANToM's end point.
This is ``rhmpc simulate --predictor generalized --duration 6`` from Python.
"""

import matplotlib.pyplot as plt
import numpy as np

from rhmpc.experiment import RunConfig, run_experiment

config = RunConfig(predictor="generalized", scenario="fixed-a2-top", seed=0).replace(
    **{"loop.duration": 6.0, "loop.settling": 2.0})
result, doc = run_experiment(config)
print(f"RMS error {doc['rms_error_mm']:.3f} mm, max {doc['max_error_mm']:.3f} mm, "
      f"RMS effort {doc['rms_effort_mNm']:.1f} mN·m")

# %%
# The POI's motion per axis, and the distance between the tool and the POI.
t = result.time
poi = 1e3 * (result.poi - np.nanmean(result.poi, axis=0))
err = 1e3 * np.linalg.norm(result.error, axis=1)
fig, (ax0, ax1) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True, constrained_layout=True)
for k, name in enumerate("xyz"):
    ax0.plot(t, poi[:, k], lw=0.8, label=name)
ax0.axvspan(t[0], config.loop.settling, color="0.92", label="settling")
ax0.set(ylabel="POI position [mm]", title="heart motion at the point of interest")
ax0.legend(ncol=4, loc="upper right", fontsize=8)
ax1.plot(t, err, color="C3", lw=0.8)
ax1.set(xlabel="time [s]", ylabel="‖tool − POI‖ [mm]", title="tracking error")
plt.show()
