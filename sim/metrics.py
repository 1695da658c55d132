"""Metrics of a run: tracking error, control effort, timing statistics."""

from __future__ import annotations

import math

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


class TickHistogram:
    """Per-tick durations as a histogram of ``resolution_ns`` bins: memory flat in run length.

    Durations up to ``span_ns`` fall in bins; longer ones are kept exactly (rare: stalls).
    Percentiles are the inverted-CDF sample quantiles (the smallest duration with at least the
    fraction ``q`` of the ticks at or below it) rounded down to the bin, so each is exact to
    ``resolution_ns`` (10 ns by default); ``max`` and ``mean`` are exact.
    """

    def __init__(self, resolution_ns: int = 10, span_ns: int = 2_000_000) -> None:
        self.resolution = int(resolution_ns)
        self.counts = np.zeros(span_ns // self.resolution, dtype=np.int64)
        self.overflow: list[int] = []
        self.n, self.total, self.max = 0, 0, 0

    def add(self, ns: np.ndarray) -> None:
        ns = np.asarray(ns, dtype=np.int64)
        if ns.size == 0:
            return
        bins = ns // self.resolution
        inside = bins < self.counts.size
        self.counts += np.bincount(bins[inside], minlength=self.counts.size)
        self.overflow.extend(ns[~inside].tolist())
        self.n += int(ns.size)
        self.total += int(ns.sum())
        self.max = max(self.max, int(ns.max()))

    def quantile_ns(self, q: float) -> float:
        """The inverted-CDF ``q`` quantile [ns], rounded down to the bin width."""
        rank = max(1, math.ceil(q * self.n))  # the rank-th smallest duration
        cumulative = np.cumsum(self.counts)
        if rank <= cumulative[-1]:
            return float(int(np.searchsorted(cumulative, rank)) * self.resolution)
        return float(sorted(self.overflow)[rank - int(cumulative[-1]) - 1])

    def stats_us(self) -> dict[str, float]:
        """p50 / p99 / p999 / max / mean [µs] (NaN without ticks)."""
        if self.n == 0:
            return {k: float("nan") for k in ("p50", "p99", "p999", "max", "mean")}
        out = {name: self.quantile_ns(q) / 1e3
               for name, q in (("p50", 0.5), ("p99", 0.99), ("p999", 0.999))}
        out["max"] = self.max / 1e3
        out["mean"] = self.total / self.n / 1e3
        return out


class RunningTracking:
    """:func:`tracking_metrics` accumulated chunk by chunk (sums of squares, counts, maxima).

    Same definitions: NaN errors (no truth) are skipped per axis and per norm. Sums are per
    chunk (numpy's pairwise sum) then over chunks, so the results differ from the whole-array
    ones only in the last bits (relative 1e-15).
    """

    def __init__(self, dim: int = 3) -> None:
        self.norm2, self.n_norm, self.max_norm = 0.0, 0, -math.inf
        self.axis2, self.n_axis = np.zeros(dim), np.zeros(dim, dtype=np.int64)
        self.effort2, self.total2, self.n_effort = 0.0, 0.0, 0

    def add(self, error: np.ndarray, tau_mpc: np.ndarray, tau_total: np.ndarray) -> None:
        """Add ticks: ``error`` (n, 3) [m], ``tau_mpc`` and ``tau_total`` (n, nv) [N·m]."""
        if error.shape[0] == 0:
            return
        sq = np.square(error)
        finite = np.isfinite(sq)
        self.axis2 += np.where(finite, sq, 0.0).sum(axis=0)
        self.n_axis += finite.sum(axis=0)
        norm2 = sq.sum(axis=1)
        ok = np.isfinite(norm2)
        if ok.any():
            self.norm2 += float(norm2[ok].sum())
            self.n_norm += int(ok.sum())
            self.max_norm = max(self.max_norm, float(np.sqrt(norm2[ok].max())))
        self.effort2 += float(np.square(tau_mpc).sum())
        self.total2 += float(np.square(tau_total).sum())
        self.n_effort += int(tau_mpc.shape[0])

    def result(self) -> dict:
        """The dict of :func:`tracking_metrics` [mm, mN·m]."""
        nan = float("nan")
        with np.errstate(invalid="ignore", divide="ignore"):
            axis = 1e3 * np.sqrt(self.axis2 / self.n_axis)
        return {
            "rms_error_mm": 1e3 * math.sqrt(self.norm2 / self.n_norm) if self.n_norm else nan,
            "max_error_mm": 1e3 * self.max_norm if self.n_norm else nan,
            "rms_error_axis_mm": axis.tolist(),
            "rms_effort_mNm": 1e3 * math.sqrt(self.effort2 / self.n_effort)
            if self.n_effort else nan,
            "rms_total_torque_mNm": 1e3 * math.sqrt(self.total2 / self.n_effort)
            if self.n_effort else nan,
        }
