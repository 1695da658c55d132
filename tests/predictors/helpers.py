"""Small motion sources and signal helpers for the predictor tests (no dependency on
`rhmpc.sim`)."""

from __future__ import annotations

import numpy as np
import pytest

#: Predictors whose tests take several times the others' (the combination runs every member).
SLOW = frozenset({"combination"})


def each(names) -> list:
    """``names`` as the parameters of a test, those of :data:`SLOW` marked slow."""
    return [pytest.param(n, marks=pytest.mark.slow) if n in SLOW else n for n in names]


class HarmonicSource:
    """p(t) = offset + Σ_i amp[:, i] sin(2π(i+1) f t + phase[:, i]) [m]; (d,) or (n, d)."""

    def __init__(self, f_hz=1.2, amp=None, phase=None, offset=None, breathing=None):
        self.f = f_hz
        self.amp = np.asarray(
            amp
            if amp is not None
            else [[4e-3, 1.5e-3, 0.7e-3], [2e-3, 1e-3, 0.3e-3], [3e-3, 0.5e-3, 0.2e-3]]
        )
        d, m = self.amp.shape
        self.phase = np.asarray(
            phase if phase is not None else np.linspace(0.3, 2.5, d * m).reshape(d, m)
        )
        self.offset = np.asarray(offset if offset is not None else [0.01, 0.2, 0.05][:d])
        self.breathing = breathing  # (f_hz, amplitude (d,)) or None

    def position(self, t):
        t = np.asarray(t, dtype=float)
        tt = np.atleast_1d(t)[:, None, None]
        i = np.arange(1, self.amp.shape[1] + 1)
        p = self.offset + (self.amp * np.sin(2 * np.pi * self.f * i * tt + self.phase)).sum(-1)
        if self.breathing is not None:
            fb, ab = self.breathing
            p = p + np.asarray(ab) * np.sin(2 * np.pi * fb * tt[:, :, 0])
        return p[0] if t.ndim == 0 else p


def run(predictor, z, steps=1):
    """Feed samples ``z`` (T, d) one by one; return forecasts (T, steps, d) made after each."""
    out = np.empty((len(z), steps, z.shape[1]))
    for k, zk in enumerate(z):
        predictor.update(zk)
        out[k] = predictor.predict(steps)
    return out


def forecast_errors(forecasts, truth, k):
    """‖ẑ_{n+k|n} − p_{n+k}‖ for every n with a truth (array of length T − k)."""
    return np.linalg.norm(forecasts[:-k, k - 1] - truth[k:], axis=-1)


def tracked_points(T: int, dt: float, points: int = 4, seed: int = 0, noise: float = 5e-6):
    """(T, P, 3) [m]: P points of one beating surface (a shared 1.2 Hz motion, each point with
    its own gain and offset, breathing at 0.25 Hz) plus white noise σ ``noise``; POI row 0."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) * dt
    beat = HarmonicSource(f_hz=1.2).position(t) - HarmonicSource(f_hz=1.2).offset
    breath = np.sin(2 * np.pi * 0.25 * t)[:, None] * np.array([1e-3, 0.5e-3, 2e-3])
    out = np.empty((T, points, 3))
    for p in range(points):
        gain = rng.uniform(0.6, 1.4, 3)
        out[:, p] = 0.05 + 0.01 * p + gain * beat + (1 + 0.2 * p) * breath
    return out + noise * rng.standard_normal(out.shape)


def feed(predictor, stream, steps: int, upto: int | None = None) -> np.ndarray:
    """Feed a (T, P, d) stream (POI row 0, the others as ``others``) and return the forecasts
    (T, steps, d) issued after each update (NaN after ``upto``)."""
    T = stream.shape[0] if upto is None else upto
    out = np.full((stream.shape[0], steps, stream.shape[2]), np.nan)
    for n in range(T):
        others = stream[n, 1:] if stream.shape[1] > 1 else None
        predictor.update(stream[n, 0], others)
        out[n] = predictor.predict(steps)
    return out
