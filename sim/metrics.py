"""Metrics of a run: tracking error, control effort, timing statistics."""

from __future__ import annotations

import numpy as np


def timing_stats(ns: np.ndarray) -> dict[str, float]:
    """p50 / p99 / max / mean of per-tick durations given in nanoseconds, reported in µs."""
    us = np.asarray(ns, dtype=float) / 1e3
    if us.size == 0:
        return {"p50": float("nan"), "p99": float("nan"), "max": float("nan"), "mean": float("nan")}
    p50, p99 = np.percentile(us, [50, 99])
    return {"p50": float(p50), "p99": float(p99), "max": float(us.max()), "mean": float(us.mean())}


def rms(x: np.ndarray, axis: int | None = None) -> np.ndarray:
    """Root mean square, ignoring NaN."""
    return np.sqrt(np.nanmean(np.square(x), axis=axis))


def tracking_metrics(error: np.ndarray, tau_mpc: np.ndarray, tau_total: np.ndarray) -> dict:
    """3-D position error RMS / max [mm] and RMS control effort [mN·m] over the given ticks.

    ``error`` is (n, 3) end-effector minus POI in metres; efforts are (n, nv) in N·m. The effort
    is the RMS over time of the Euclidean norm of the joint torque vector.
    """
    norm = np.linalg.norm(error, axis=1)
    return {
        "rms_error_mm": float(1e3 * rms(norm)),
        "max_error_mm": float(1e3 * np.nanmax(norm)) if norm.size else float("nan"),
        "rms_error_axis_mm": (1e3 * rms(error, axis=0)).tolist(),
        "rms_effort_mNm": float(1e3 * rms(np.linalg.norm(tau_mpc, axis=1))),
        "rms_total_torque_mNm": float(1e3 * rms(np.linalg.norm(tau_total, axis=1))),
    }
