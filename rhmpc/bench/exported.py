"""The whole controller timed tick by tick in a closed loop of its own, its own RLS refreshing
(``rhmpc bench --controller c``; the module docstring of :mod:`rhmpc.bench.ticks` states the
protocol)."""

from __future__ import annotations

import gc

import numpy as np

from rhmpc.control.settings import MPCSettings
from rhmpc.sim.loop.metrics import warm_ns
from rhmpc.timing.yardstick import GainTick

__all__ = ["exported_ticks", "percentiles"]


def percentiles(values: np.ndarray) -> dict[str, float]:
    """``p50``, ``p99``, ``max`` and ``mean`` of timings (their unit)."""
    return {
        "p50": float(np.percentile(values, 50)),
        "p99": float(np.percentile(values, 99)),
        "max": float(np.max(values)),
        "mean": float(np.mean(values)),
    }


def exported_ticks(robot: str, settings: MPCSettings, traj: np.ndarray, warmup: int,
                   disable_gc: bool = True, reading_delay: int = 0) -> dict:
    """The whole controller in a closed loop of its own on ``traj`` (n + N + 1, 3), its own
    generalized RLS refreshing: every tick timed inside C, refresh ticks included, beside the
    gain tick (see the module docstring). Each tick's step takes the reading of
    ``reading_delay`` ticks before (``rhmpc_step_delayed``: the observer's correction at that
    tick and as many predictions; none at the first ticks). Returns ``exported_tick_us``,
    ``exported_tick_g``, ``exported_refresh_us``, its levels, fallbacks and the tracking of the
    linear model."""
    from rhmpc.experiment import RunConfig
    from rhmpc.experiment.assembly import build_controller, build_reference, build_robot
    from rhmpc.sim.loop.clock import clock_for_rate

    config = RunConfig(robot=robot, mpc=settings)
    model, arm = build_robot(config)
    reference = build_reference(config, None, None, clock_for_rate(config.loop, 257.0))
    c, center = build_controller(config, model, arm, reference, "c"), traj.mean(axis=0)
    c.place(center)
    gain, every, n = GainTick(c.mpc), config.loop.downsample, traj.shape[0] - c.N - 1
    tick_ns, gain_ns = np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    level, err, refreshed = np.zeros(n, dtype=np.int64), np.zeros(n), np.zeros(n, dtype=bool)
    x, u_prev = np.zeros(arm.nx), np.zeros(arm.nu)
    readings = np.full((n, arm.nu), np.nan)
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
            readings[k] = arm.q0 + x[: arm.nu]
            c.step(k, readings[k - reading_delay] if k >= reading_delay else readings[0] * np.nan,
                   reading_delay)
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
        "controller": "c", "exported_reading_delay_ticks": reading_delay,
        "exported_tick_us": percentiles(us),
        "c_tick_us": percentiles(us[~refreshed[sl]]),
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
