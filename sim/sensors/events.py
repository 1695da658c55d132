"""Rare events of a sensor: echo outliers (position jumps) and dropouts (missing samples)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from rhmpc.sim.sensors.stream import SampleStream


@dataclass(frozen=True)
class EchoOutliers:
    """Ultrasound echo outliers: short jumps of several millimetres (Tuna et al. §III-A, §VIII).

    Events arrive as a Poisson process of ``rate`` per second. Each lasts a duration drawn
    uniformly in ``duration`` and adds a constant offset o = a·u to the samples it covers,
    with u a random unit vector (±1 in 1-D) and a uniform in ``amplitude``.

    Attributes
    ----------
    rate : float
        Mean number of events per second [1/s].
    amplitude : tuple of float
        (min, max) jump size [m].
    duration : tuple of float
        (min, max) event length [s].
    """

    rate: float = 0.05
    amplitude: tuple[float, float] = (2e-3, 6e-3)
    duration: tuple[float, float] = (2e-3, 8e-3)

    def __post_init__(self) -> None:
        if not self.rate >= 0:
            raise ValueError("outlier rate must be ≥ 0 [1/s]")
        if not 0 <= self.amplitude[0] <= self.amplitude[1]:
            raise ValueError("outlier amplitude must be (min, max) with 0 ≤ min ≤ max [m]")
        if not 0 < self.duration[0] <= self.duration[1]:
            raise ValueError("outlier duration must be (min, max) with 0 < min ≤ max [s]")

    def events(self, t0: float, t1: float, dim: int,
               rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(start [s], length [s], offset (m, dim) [m]) of the events in ``[t0, t1]``."""
        n = rng.poisson(self.rate * max(t1 - t0, 0.0))
        start = np.sort(rng.uniform(t0, t1, n))
        length = rng.uniform(*self.duration, n)
        u = rng.standard_normal((n, dim))
        u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-12)
        return start, length, u * rng.uniform(*self.amplitude, n)[:, None]

    def apply(self, stream: SampleStream, rng: np.random.Generator) -> SampleStream:
        if stream.t.size == 0:
            return stream
        start, length, offset = self.events(stream.t[0], stream.t[-1], stream.dim, rng)
        z = stream.z.copy()
        for s, d, o in zip(start, length, offset, strict=True):
            i0, i1 = np.searchsorted(stream.t, [s, s + d])
            z[i0:max(i1, i0 + 1)] += o  # every event hits at least one sample
        return replace(stream, z=z)


@dataclass(frozen=True)
class Dropouts:
    """Occlusions and tracking losses: samples inside an event are NaN (Richa et al. §II).

    Events arrive as a Poisson process of ``rate`` per second; their lengths are log-uniform
    in ``duration`` (specular reflections ≈ 0.12 s, instrument occlusions up to 3 s).

    Attributes
    ----------
    rate : float
        Mean number of events per second [1/s].
    duration : tuple of float
        (min, max) event length [s].
    """

    rate: float = 0.02
    duration: tuple[float, float] = (0.12, 3.0)

    def __post_init__(self) -> None:
        if not self.rate >= 0:
            raise ValueError("dropout rate must be ≥ 0 [1/s]")
        if not 0 < self.duration[0] <= self.duration[1]:
            raise ValueError("dropout duration must be (min, max) with 0 < min ≤ max [s]")

    def intervals(self, t0: float, t1: float, rng: np.random.Generator) -> np.ndarray:
        """(m, 2) array of [start, end) dropout intervals [s] in ``[t0, t1]``."""
        n = rng.poisson(self.rate * max(t1 - t0, 0.0))
        start = np.sort(rng.uniform(t0, t1, n))
        lo, hi = np.log(self.duration[0]), np.log(self.duration[1])
        length = np.exp(rng.uniform(lo, hi, n))
        return np.column_stack([start, start + length])

    def apply(self, stream: SampleStream, rng: np.random.Generator) -> SampleStream:
        if stream.t.size == 0:
            return stream
        z = stream.z.copy()
        for s, e in self.intervals(stream.t[0], stream.t[-1], rng):
            i0, i1 = np.searchsorted(stream.t, [s, e])
            z[i0:i1] = np.nan
        return replace(stream, z=z)
