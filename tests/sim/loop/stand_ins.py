"""Stand-ins for loop tests: a harmonic heart and an ideal stream.

They are independent of the project's heart models, so the loop's plumbing is tested on its own.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class HarmonicHeart:
    """p(t) = Σ_h a_h sin(2π h f t + φ_h) per axis [m]; 1.66 Hz, ~8 mm peak to peak."""

    def __init__(self, f: float = 1.66, amplitude: float = 4e-3, dim: int = 3) -> None:
        self.f, self.dim = f, dim
        self.amp = amplitude * np.array([1.0, 0.5, 0.3, 0.15])[:, None] * np.linspace(1, 0.5, dim)
        self.phase = np.array([0.0, 0.7, 1.9, 2.6])[:, None] + np.arange(dim)

    def position(self, t):
        t = np.asarray(t, dtype=float)
        h = np.arange(1, 5)[:, None, None]
        p = np.sum(self.amp[:, None, :] * np.sin(2 * np.pi * h * self.f * t[None, ..., None]
                                                 + self.phase[:, None, :]), axis=0)
        return p


@dataclass
class Stream:
    t: np.ndarray
    z: np.ndarray
    arrival: np.ndarray


def ideal_stream(source, duration: float, rate: float = 2000.0, latency: float = 0.0) -> Stream:
    t = np.arange(int(duration * rate) + 1) / rate
    return Stream(t=t, z=source.position(t), arrival=t + latency)
