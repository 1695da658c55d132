"""
Forecasts of the predictors
===========================

Each predictor reads the physical sonomicrometer's samples of a replica (every second sample of
the 257-Hz instrument) one at a time, and forecasts three samples (about 23 ms) ahead. The figure
shows the forecasts over two heartbeats against the true motion, and each predictor's RMS miss
after a 10-s warm-up.
"""

import matplotlib.pyplot as plt
import numpy as np

from rhmpc.predictors import make_predictor
from rhmpc.sim.heart import make_scenario
from rhmpc.sim.sensors import sensor_from_name

rng = np.random.default_rng(4)
scenario = make_scenario("fixed-a2-top", rng, duration=20.0)
sensor = sensor_from_name("sonomicrometry", dim=3)
stream = sensor.measure(scenario.source, scenario.duration, np.random.default_rng(4))
t, z = stream.t[::2], stream.z[::2]
dt = float(np.median(np.diff(t)))
ahead, warm = 3, int(10 / dt)
names = ("hold", "one-step", "generalized", "ekf", "dual-ekf", "wflc")
forecast = {}
for name in names:
    p = make_predictor(name, dt)
    f = np.full_like(z, np.nan)
    for n in range(len(z) - ahead):
        p.update(z[n])
        if n >= warm:
            f[n + ahead] = p.predict(ahead)[ahead - 1]
    forecast[name] = f

truth = scenario.source.position(t)
rms = {name: 1e3 * np.sqrt(np.nanmean(np.sum((f - truth) ** 2, axis=1)))
       for name, f in forecast.items()}
print({k: round(float(v), 3) for k, v in rms.items()})

# %%
# The x axis over two beats, and the RMS miss of each predictor.
window = (t > 15.0) & (t < 16.5)
center = np.mean(truth[:, 0])
fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True,
                               gridspec_kw={"width_ratios": [2, 1]})
ax0.plot(t[window], 1e3 * (truth[window, 0] - center), "k", lw=2, label="true motion")
for name in names:
    ax0.plot(t[window], 1e3 * (forecast[name][window, 0] - center), lw=0.9, label=name)
ax0.set(xlabel="time [s]", ylabel="x [mm]", title="23-ms-ahead forecasts")
ax0.legend(fontsize=7, ncol=2)
ax1.barh(list(rms), list(rms.values()), color=[f"C{i}" for i in range(len(names))])
ax1.set(xlabel="RMS miss [mm]", title="after the warm-up")
ax1.invert_yaxis()
plt.show()
