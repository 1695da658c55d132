"""Metrics of a run: tracking error, control effort, timing statistics."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np


def warm_ns(fn: Callable[..., object], *args, repeats: int = 3) -> int:
    """The least time [ns] of ``repeats`` consecutive calls ``fn(*args)``: the work itself, with
    the caches it warms, not the state the surrounding work left them in (a yardstick's
    timing)."""
    best = None
    for _ in range(repeats):
        start = time.perf_counter_ns()
        fn(*args)
        spent = time.perf_counter_ns() - start
        best = spent if best is None or spent < best else best
    return best


def rms(x: np.ndarray, axis: int | None = None) -> np.ndarray:
    """Root mean square, ignoring NaN."""
    return np.sqrt(np.nanmean(np.square(x), axis=axis))


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
        counted = np.bincount(bins[inside])  # up to the longest tick: not the whole span
        self.counts[: counted.size] += counted
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


class RunningError:
    """RMS, max and per-axis RMS of error vectors accumulated chunk by chunk [m → mm].

    For vectors e_j (n, 3): RMS = √(Σ‖e_j‖²/n), max = max ‖e_j‖, per axis √(Σ e_{j,a}²/n_a).
    A vector with a non-finite component is skipped for the norm (and per axis where that
    axis is not finite). Sums are per chunk (numpy's pairwise sum) then over chunks, so the
    results differ from the whole-array ones only in the last bits (relative 1e-15).
    """

    def __init__(self, dim: int = 3) -> None:
        self.norm2, self.n, self.max_norm = 0.0, 0, -math.inf
        self.axis2, self.n_axis = np.zeros(dim), np.zeros(dim, dtype=np.int64)

    def add(self, error: np.ndarray) -> None:
        """Add error vectors ``error`` (n, 3) [m]."""
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
            self.n += int(ok.sum())
            self.max_norm = max(self.max_norm, float(np.sqrt(norm2[ok].max())))

    def result(self, suffix: str = "") -> dict:
        """``rms_error{suffix}_mm``, ``max_error{suffix}_mm``, ``rms_error_axis{suffix}_mm``
        (NaN without a finite vector)."""
        nan = float("nan")
        with np.errstate(invalid="ignore", divide="ignore"):
            axis = 1e3 * np.sqrt(self.axis2 / self.n_axis)
        return {f"rms_error{suffix}_mm": 1e3 * math.sqrt(self.norm2 / self.n) if self.n else nan,
                f"max_error{suffix}_mm": 1e3 * self.max_norm if self.n else nan,
                f"rms_error_axis{suffix}_mm": axis.tolist()}


class RunningTracking:
    """The run's tracking metrics accumulated chunk by chunk: the errors' :class:`RunningError`
    and the efforts' sums of squares. NaN errors (no truth) are skipped per axis and per norm.
    """

    def __init__(self, dim: int = 3) -> None:
        self.error = RunningError(dim)
        self.effort2, self.total2, self.n_effort = 0.0, 0.0, 0

    def add(self, error: np.ndarray, tau_mpc: np.ndarray, tau_total: np.ndarray) -> None:
        """Add ticks: ``error`` (n, 3) [m], ``tau_mpc`` and ``tau_total`` (n, nv) [N·m]."""
        if error.shape[0] == 0:
            return
        self.error.add(error)
        self.effort2 += float(np.square(tau_mpc).sum())
        self.total2 += float(np.square(tau_total).sum())
        self.n_effort += int(tau_mpc.shape[0])

    def result(self) -> dict:
        """RMS and max error, per-axis RMS [mm], RMS ‖τ_mpc‖ and ‖τ‖ [mN·m]: the RMS over time of
        the Euclidean norm of the joint torque vector."""
        nan = float("nan")
        n = self.n_effort
        return {**self.error.result(),
                "rms_effort_mNm": 1e3 * math.sqrt(self.effort2 / n) if n else nan,
                "rms_total_torque_mNm": 1e3 * math.sqrt(self.total2 / n) if n else nan}


class MeasuredScore:
    """The tool's distance to the POI where the POI was measured: at each recorded sample's
    instant, never between samples.

    For every sample k with ``start`` ≤ t_k < ``stop`` the error is e_k = p_ee(t_k) − p_k, with
    p_ee(t_k) linear between the two ticks around t_k (exact when t_k lies on a tick, as a
    25-Hz frame does on the 2-kHz grid) and p_k the sample placed in the workspace. A sample
    that is no measurement (non-finite), or that the controller took as an outlier, is left
    out and counted.

    Parameters
    ----------
    t : ndarray (n,)
        The samples' instants in the run's time [s], increasing.
    p : ndarray (n, 3)
        The samples placed in the workspace [m] (NaN: no measurement).
    start, stop : float
        The scored span [s]: the settling's end and the run's end (half-open).
    Ts : float
        Control period [s]; the state after tick i is that of time (i + 1)·Ts.
    """

    #: Instants closer than this are the same instant [s].
    SNAP = 1e-9

    def __init__(self, t: np.ndarray, p: np.ndarray, start: float, stop: float,
                 Ts: float) -> None:
        self.t, self.Ts = np.asarray(t, dtype=float), float(Ts)
        self.p = np.asarray(p, dtype=float).reshape(self.t.size, -1)
        self.first = int(np.searchsorted(self.t, start - self.SNAP))
        self.stop = int(np.searchsorted(self.t, stop - self.SNAP))
        self.outlier = np.zeros(self.t.size, dtype=bool)
        self.error = RunningError(self.p.shape[1])
        self.pending: list[tuple[np.ndarray, np.ndarray]] = []  # (indices, errors) to fold
        self._next = self.first  # the first sample not yet placed against the tool
        self._last: tuple[float, np.ndarray] | None = None  # the previous chunk's last state

    @property
    def last(self) -> float:
        """The last sample's instant [s]: the recording says nothing of the heart after it."""
        return float(self.t[-1]) if self.t.size else -math.inf

    @property
    def unmeasured(self) -> int:
        """Samples of the scored span that are no measurements."""
        span = self.p[self.first : self.stop]
        return int((~np.isfinite(span).all(axis=1)).sum())

    def rows(self, c0: int, m: int) -> np.ndarray:
        """Which of the states after ticks c0 … c0 + m − 1 lie at or next to a sample's instant
        in the scored span: (m,) bool (what a trace keeps to recompute the score)."""
        j = self.t[self.first : self.stop] / self.Ts - 1.0 - c0  # fractional row of each
        j = j[(j > -1.0) & (j < m)]
        keep = np.zeros(m, dtype=bool)
        for rows in (np.floor(j + 1e-6), np.ceil(j - 1e-6)):
            rows = rows.astype(int)
            keep[rows[(rows >= 0) & (rows < m)]] = True
        return keep

    def add(self, c0: int, ee: np.ndarray) -> None:
        """The tool's positions ``ee`` (m, 3) [m] after ticks c0 … c0 + m − 1: the errors of the
        samples whose instants they reach, kept until :meth:`fold` knows the outliers."""
        times = (c0 + 1 + np.arange(ee.shape[0])) * self.Ts
        if self._last is not None:
            times, ee = np.r_[self._last[0], times], np.vstack([self._last[1], ee])
        self._last = (float(times[-1]), ee[-1].copy())
        first = max(self._next, int(np.searchsorted(self.t, times[0] - self.SNAP)))
        stop = min(self.stop, int(np.searchsorted(self.t, times[-1] + self.SNAP, "right")))
        if stop <= first:
            return
        k = np.arange(first, stop)
        tool = np.column_stack([np.interp(self.t[k], times, ee[:, a])
                                for a in range(ee.shape[1])])
        self.pending.append((k, tool - self.p[k]))
        self._next = stop

    def fold(self, outliers: list[float], before: float = math.inf) -> None:
        """Fold the kept errors of instants before ``before`` [s] into the score, leaving out
        the samples measured at the stamps ``outliers`` [s] (and the non-finite ones)."""
        stamps = np.sort(np.asarray(outliers, dtype=float))
        keep = []
        for k, e in self.pending:
            if self.t[k[-1]] >= before:
                keep.append((k, e))
                continue
            if stamps.size:
                at = np.clip(np.searchsorted(stamps, self.t[k]), 1, stamps.size) - 1
                near = np.minimum(np.abs(stamps[at] - self.t[k]),
                                  np.abs(stamps[np.minimum(at + 1, stamps.size - 1)]
                                         - self.t[k]))
                self.outlier[k] = near <= self.SNAP
            self.error.add(e[~self.outlier[k]])
        self.pending = keep

    @property
    def outliers(self) -> int:
        """Samples of the scored span taken as outliers."""
        return int(self.outlier[self.first : self.stop].sum())

    def samples(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t (n,) [s], p (n, 3) [m], scored (n,) bool): every sample, and whether it is in
        the score (in the span, measured, not an outlier)."""
        scored = np.zeros(self.t.size, dtype=bool)
        scored[self.first : self.stop] = True
        scored &= np.isfinite(self.p).all(axis=1) & ~self.outlier
        return self.t, self.p, scored

    def result(self) -> dict:
        """``rms_error_mm``, ``max_error_mm``, ``rms_error_axis_mm`` and ``scored_samples``."""
        return {**self.error.result(), "scored_samples": self.error.n}
