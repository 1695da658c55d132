"""The exported controller of ``rhmpc export`` timed tick by tick in a closed loop of its own
(``rhmpc bench --controller c``), and replayed against the Python controller it was generated
from (the module docstring of :mod:`rhmpc.bench.ticks` states the protocol)."""

from __future__ import annotations

import gc

import numpy as np

from rhmpc.control.settings import MPCSettings
from rhmpc.sim.loop.metrics import warm_ns
from rhmpc.timing.yardstick import GainTick

__all__ = ["c_against_python", "exported_ticks", "percentiles"]


def percentiles(values: np.ndarray) -> dict[str, float]:
    """``p50``, ``p99``, ``max`` and ``mean`` of timings (their unit)."""
    return {
        "p50": float(np.percentile(values, 50)),
        "p99": float(np.percentile(values, 99)),
        "max": float(np.max(values)),
        "mean": float(np.mean(values)),
    }


def exported_ticks(robot: str, settings: MPCSettings, traj: np.ndarray, warmup: int,
                   disable_gc: bool = True) -> dict:
    """The whole exported controller in a closed loop of its own on ``traj`` (n + N + 1, 3):
    every tick timed inside C, refresh ticks included, beside the gain tick (see the module
    docstring). Returns ``exported_tick_us``, ``exported_tick_g``, ``exported_refresh_us``,
    its levels, fallbacks and the tracking of the linear model."""
    from rhmpc.control.export import controller_in_c
    from rhmpc.experiment import RunConfig
    from rhmpc.experiment.assembly import deployable

    config = RunConfig(robot=robot, mpc=settings)
    python = deployable(config, 257.0)
    c, arm, center = controller_in_c(python, robot), python.mpc.arm, traj.mean(axis=0)
    c.place(center)
    gain, every, n = GainTick(python.mpc), config.loop.downsample, traj.shape[0] - c.N - 1
    tick_ns, gain_ns = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    level, err, refreshed = np.zeros(n, dtype=np.int64), np.zeros(n), np.zeros(n, dtype=bool)
    x, u_prev = np.zeros(arm.nx), np.zeros(arm.nu)
    gc_was_enabled = gc.isenabled()
    if disable_gc:
        gc.collect()
        gc.disable()
    try:
        for k in range(n):
            refresh_ns = 0
            if k % every == 1:  # a sample taken one tick ago arrives
                c.refresh(k, traj[k - 1] - center, (k - 1) * arm.Ts)
                refresh_ns, refreshed[k] = c.refresh_ns, True
            c.step(k, arm.q0 + x[: arm.nu])
            tick_ns[k], level[k] = c.step_ns + refresh_ns, c.stats.level
            gain_ns[k] = warm_ns(gain, c.x_hat, c.horizon(k), u_prev)
            u_prev = c.u
            x = arm.A @ x + arm.B @ u_prev
            err[k] = float(np.linalg.norm(arm.C @ x + arm.y0 - traj[k + 1]))
    finally:
        if disable_gc and gc_was_enabled:
            gc.enable()
    sl = slice(warmup, n)
    us, g = tick_ns[sl] * 1e-3, np.median(gain_ns[sl]) * 1e-3
    stats = c.stats
    return {
        "controller": "c",
        "exported_tick_us": percentiles(us),
        "c_tick_us": percentiles(us[~refreshed[sl]]),
        "c_vs_python_max_frac": c_against_python(python, c, traj, center, every),
        "exported_tick_g": {k: v / g for k, v in percentiles(us).items() if k != "mean"},
        "exported_gain_tick_us": percentiles(gain_ns[sl] * 1e-3),
        "exported_refresh_tick_us": percentiles(us[refreshed[sl]]) if refreshed[sl].any() else None,
        "exported_levels": {str(v): int(np.sum(level[sl] == v)) for v in (0, 1, 2, 3)},
        "exported_level_tick_us": {str(v): percentiles(us[level[sl] == v]) for v in (1, 2, 3)
                                   if np.any(level[sl] == v)},
        "exported_fallbacks": dict(stats.fallbacks),
        "exported_failures": dict(stats.failures),
        "exported_predictor": config.predictor,
        "exported_tracking_rms_mm": float(1e3 * np.sqrt(np.mean(err[sl] ** 2))),
        "exported_library": c.library,
    }


def c_against_python(python, c, traj: np.ndarray, center: np.ndarray, every: int) -> float:
    """max over the ticks of ``|τ_C − τ_Python|`` / τ_max: both controllers reset, placed
    at ``center`` and fed the same samples of ``traj`` and the same encoder readings (those of
    the linear model driven by the C's torque)."""
    c.reset()
    c.place(center)
    python.reset()
    python.reference.place(center)
    arm, n = python.mpc.arm, traj.shape[0] - c.N - 1
    x, worst = np.zeros(arm.nx), 0.0
    for k in range(n):
        if k % every == 1:
            for controller in (c, python):
                controller.refresh(k, traj[k - 1] - center, (k - 1) * arm.Ts)
        q = arm.q0 + x[: arm.nu]
        tau_c, tau_py = c.step(k, q), python.step(k, q)
        worst = max(worst, float(np.max(np.abs(tau_c - tau_py) / python.torque_limit)))
        x = arm.A @ x + arm.B @ c.u
    return worst
