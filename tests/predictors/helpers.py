"""Small motion sources and signal helpers for the predictor tests (no dependency on `sim`)."""

from __future__ import annotations

import numpy as np


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
