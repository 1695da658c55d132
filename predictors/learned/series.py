"""Training series of the fitted predictors: validation, statistics and the delay embedding.

A *series* is one recording on the predictor's sampling grid (period ``dt``): an array
(T, P, d) of positions in metres, T samples of P tracked points of dimension d, the point of
interest (POI) in row 0 and NaN where a sample is missing. A (T, d) array is a series of one
point. ``fit`` takes one series or a list of them (several recordings, or the first part of
one).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["as_series", "channel_stats", "fill_forward", "relative_windows"]


def as_series(series, points: int | None = None) -> list[np.ndarray]:
    """The series as a list of float (T, P, d) arrays, checked; ``points``: keep the first
    ``points`` points of each (1: the POI only).

    Raises
    ------
    ValueError
        An empty list, a wrong shape, series that disagree on P or d, or a series without a
        complete POI sample.
    """
    items = [series] if isinstance(series, np.ndarray) else list(series)
    if not items:
        raise ValueError("fit needs at least one series (T, P, d) in metres")
    out = []
    for i, s in enumerate(items):
        a = np.array(s, dtype=float)
        if a.ndim == 2:
            a = a[:, None, :]
        if a.ndim != 3 or a.shape[0] < 2 or a.shape[2] < 1:
            raise ValueError(f"series {i} has shape {np.shape(s)}; expected (T, P, d) or (T, d)")
        if points is not None:
            if a.shape[1] < points:
                raise ValueError(f"series {i} holds {a.shape[1]} point(s); {points} needed")
            a = a[:, :points]
        a[~np.isfinite(a)] = np.nan
        if not np.isfinite(a[:, 0]).all(axis=1).any():
            raise ValueError(f"series {i}: its point of interest (row 0) is never measured")
        out.append(a)
    if len({a.shape[1:] for a in out}) > 1:
        raise ValueError("the series disagree on (P, d): " + ", ".join(
            str(a.shape[1:]) for a in out))
    return out


def channel_stats(series: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation (P·d,) of every channel over the measured samples of all
    series (a channel that does not move gets σ = 1)."""
    flat = np.concatenate([s.reshape(s.shape[0], -1) for s in series])
    mean = np.nanmean(flat, axis=0)
    std = np.nanstd(flat, axis=0)
    mean = np.where(np.isfinite(mean), mean, 0.0)
    std = np.where(np.isfinite(std) & (std > 0.0), std, 1.0)
    return mean, std


def fill_forward(a: np.ndarray) -> np.ndarray:
    """(T, C) with every NaN replaced by the channel's previous value (its first value before
    it is first seen; 0 for a channel never seen): the inputs a model sees through a gap."""
    out = np.array(a, dtype=float)
    for c in range(out.shape[1]):
        col = out[:, c]
        ok = np.isfinite(col)
        if not ok.any():
            col[:] = 0.0
            continue
        idx = np.where(ok, np.arange(col.size), 0)
        np.maximum.accumulate(idx, out=idx)
        idx[: np.argmax(ok)] = np.argmax(ok)
        out[:, c] = col[idx]
    return out


def relative_windows(rows: np.ndarray, order: int) -> np.ndarray:
    """(T − N + 1, (N − 1)·C) regressors [r_{n−1} − r_n; …; r_{n−N+1} − r_n] of rows (T, C),
    one per n = N − 1 … T − 1 (newest-first: the increment form of the delay embedding)."""
    T, C = rows.shape
    win = np.lib.stride_tricks.sliding_window_view(rows, order, axis=0)  # (T−N+1, C, N)
    win = win[:, :, ::-1]  # newest first
    rel = win[:, :, 1:] - win[:, :, :1]
    return rel.transpose(0, 2, 1).reshape(T - order + 1, (order - 1) * C)
