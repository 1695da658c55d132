"""A closed-loop run's result made up without the loop: the PHANToM following a heart-like POI.

The arm follows the POI through its Jacobian at home with a lag, so the tool misses it by a few
tenths of a millimetre; each refresh forecasts the next N ticks with an error that grows with the
lead; the sensor's samples are the POI plus noise. Fields as :class:`rhmpc.sim.loop.LoopResult` has
them, plus ``trace["q"]``, ``horizons`` and ``samples``.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np


def heart(t: np.ndarray) -> np.ndarray:
    """(n, 3) heart-like motion [m]: 1.2 Hz with a harmonic, and breathing at 0.25 Hz."""
    phase = np.array([0.0, 1.2, 2.2])
    ph, b = 2 * np.pi * 1.2 * t[:, None] + phase, 2 * np.pi * 0.25 * t[:, None] + phase / 2
    amp = np.array([[3.0, 2.0, 5.0]]) * 1e-3
    return amp * (np.sin(ph) + 0.3 * np.sin(2 * ph + 0.4) + 0.3 * np.sin(b))


def stand_in_run(robot, seconds: float = 3.0, Ts: float = 0.5e-3, stride: int = 1,
                 tail: float = 2.0, refresh_every: int = 8, horizon: int = 50,
                 settling: float = 1.0, seed: int = 0) -> SimpleNamespace:
    """A made-up run of ``seconds`` [s]; the trace keeps every ``stride``-th tick, then every
    tick over the last ``tail`` seconds (as the loop's decimated trace does)."""
    rng = np.random.default_rng(seed)
    n = round(seconds / Ts)
    ticks = np.arange(n)
    kept = ticks[(ticks % stride == 0) | (ticks >= n - round(tail / Ts))]
    p0 = robot.ee_position(robot.q0)
    J = robot.ee_jacobian(robot.q0)
    poi = p0 + heart((kept + 1) * Ts)
    lagged = p0 + heart((kept + 1) * Ts - 0.004)  # the tool 4 ms behind
    q = robot.q0 + (np.linalg.pinv(J) @ (lagged - p0).T).T
    ee = np.array([robot.ee_position(qk) for qk in q])
    tau = 0.02 * np.sin(2 * np.pi * 1.2 * (kept[:, None] + 1) * Ts + [0.0, 1.0, 2.0])
    tau[:10] = 1.2 * robot.torque_limit  # a few saturated ticks at the start
    trace = {"tick": kept, "time": (kept + 1) * Ts, "ee": ee, "poi": poi,
             "reference0": poi + 1e-4, "tau_mpc": 0.5 * tau, "tau_command": tau,
             "tau": np.clip(tau, -robot.torque_limit, robot.torque_limit),
             "tick_ns": np.full(kept.size, 20_000), "q": q}
    rticks = np.arange(0, n, refresh_every)
    rticks = rticks[(rticks % (refresh_every * stride) == 0) | (rticks >= n - round(tail / Ts))]
    lead = np.arange(1, horizon + 1)
    future = p0 + heart(((rticks[:, None] + lead) * Ts).ravel()).reshape(-1, horizon, 3)
    points = future + 2e-6 * lead[None, :, None] * rng.standard_normal((rticks.size, 1, 3))
    t_s = np.arange(0.0, seconds, 1 / 257)
    z = p0 + heart(t_s) + 5e-5 * rng.standard_normal((t_s.size, 3))
    z[5] = np.nan  # a missing sample
    settings = SimpleNamespace(Ts=Ts, settling=settling, settling_s=settling, horizon=horizon,
                               duration=seconds)
    return SimpleNamespace(
        settings=settings, trace=trace, stride=stride, time=trace["time"], ee=ee, poi=poi,
        reference0=trace["reference0"], tau_mpc=trace["tau_mpc"], tau=trace["tau"],
        tau_command=tau, tick_ns=trace["tick_ns"], error=ee - poi,
        horizons=(rticks, points), samples=(t_s, z))
