"""Delivery of a sensor's samples to the 2-kHz control loop (playback).

The loop reads, at tick τ_j = j·Ts, the newest *delivered* sample whose arrival ≤ τ_j. Named
playbacks (:data:`PLAYBACKS`, the setting ``playback`` of a sensor):

``"hold"`` (causal)
    zero-order hold of the newest arrived raw sample: z(τ_j) = z_k with k the newest raw
    sample, stamped with its measurement time t_k, arrival(τ_j) = τ_j + (arrival_k − t_k) ≥
    arrival_k. The samples the loop reads are 0 … 1 raw period old, varying from read to read.
``"linear"`` (causal, the default of the sensors)
    linear interpolation between raw samples k and k + 1, delivered one raw period after τ_j
    (after sample k + 1 has arrived): every sample the loop reads is one raw period old
    (3.9 ms at 257 Hz), on a uniform grid.
``"offline"`` (non-causal)
    linear interpolation delivered at τ_j, as when a prerecorded file is played back (the
    protocol of Tuna et al. 2013 §VIII): at τ_j the loop reads a value interpolated toward the
    *next* raw sample, up to one raw period (3.9 ms at 257 Hz) of the future.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from rhmpc.sim.sensors.stream import BLOCK, ArraySamples, SampledSamples, SampleStream, grid_index


@dataclass(frozen=True)
class Upsample:
    r"""Resample the stream to a faster rate (the delivery of the samples to the 2-kHz loop).

    At the output times :math:`\tau_j`, with k the newest raw sample at or before
    :math:`\tau_j`:

    .. math::

        z(\tau_j) = z_k + \frac{\tau_j - t_k}{t_{k+1} - t_k}\,(z_{k+1} - z_k)
        \quad \text{(linear)}, \qquad z(\tau_j) = z_k \quad \text{(hold)},

    the linear one NaN if either neighbour is missing. With ``causal`` the interpolated sample
    arrives one raw period after τ_j (after its newer neighbour); without, it arrives at
    τ_j + (arrival_k − t_k), as when a prerecorded file is played back (:func:`deliver`).

    The class's defaults are the offline playback; the sensors' default is the causal
    ``"linear"`` (:data:`rhmpc.sim.sensors.names.DEFAULT_PLAYBACK`, :func:`playback`).

    Attributes
    ----------
    rate : float
        Output rate [Hz].
    method : str
        ``"linear"`` or ``"hold"``.
    causal : bool
        Whether linear interpolation waits for the next raw sample.
    """

    rate: float = 2000.0
    method: str = "linear"
    causal: bool = False

    def __post_init__(self) -> None:
        if not self.rate > 0:
            raise ValueError("upsample rate must be > 0 [Hz]")
        if self.method not in ("linear", "hold"):
            raise ValueError("upsample method must be 'linear' or 'hold'")

    def apply(self, stream: SampleStream, rng: np.random.Generator) -> SampleStream:
        t_raw = stream.t
        if t_raw.size < 2:
            return stream
        n = int(np.floor((t_raw[-1] - t_raw[0]) * self.rate + 1e-9)) + 1
        tau = t_raw[0] + np.arange(n) / self.rate
        t, z, arrival = deliver(t_raw, stream.z, stream.arrival, tau, self.method, self.causal)
        return SampleStream(t, z, np.maximum.accumulate(arrival), self.rate)


def deliver(t_raw: np.ndarray, z_raw: np.ndarray, arrival_raw: np.ndarray, tau: np.ndarray,
            method: str, causal: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, z, arrival) of the delivered samples at the output times ``tau`` [s].

    ``"hold"``: z = z_k, t = t_k (the sample keeps its measurement time), arrival = τ_j +
    (arrival_k − t_k), k the newest raw sample with t_k ≤ τ_j.
    ``"linear"``: z(τ_j) = z_k + w (z_{k+1} − z_k), w = (τ_j − t_k)/(t_{k+1} − t_k), t = τ_j;
    causal: arrival = max(arrival_{k+1}, τ_j + (t_{k+1} − t_k) + (arrival_k − t_k)), i.e. one raw
    period after τ_j (every delivered sample is equally old, and never read before its newer
    neighbour has arrived); non-causal: arrival = τ_j + (arrival_k − t_k).
    """
    k = np.clip(np.searchsorted(t_raw, tau, side="right") - 1, 0, t_raw.size - 2)
    if method == "hold":
        held = np.clip(np.searchsorted(t_raw, tau + 1e-12, side="right") - 1, 0,
                       t_raw.size - 1)
        return t_raw[held].copy(), z_raw[held].copy(), tau + (arrival_raw[held] - t_raw[held])
    period = t_raw[k + 1] - t_raw[k]
    w = ((tau - t_raw[k]) / period)[:, None]
    with np.errstate(invalid="ignore"):
        z = (1.0 - w) * z_raw[k] + w * z_raw[k + 1]
    exact0 = w[:, 0] == 0.0
    z[exact0] = z_raw[k][exact0]
    delay = arrival_raw[k] - t_raw[k]
    if causal:
        arrival = np.maximum(arrival_raw[k + 1], tau + period + delay)
    else:
        arrival = tau + delay
    return tau, z, arrival


#: Named playbacks: (method, causal) of :class:`Upsample`.
PLAYBACKS: dict[str, tuple[str, bool]] = {
    "hold": ("hold", True),
    "linear": ("linear", True),
    "offline": ("linear", False),
}


def playback(name: str, rate: float) -> Upsample:
    """The named playback (:data:`PLAYBACKS`) to ``rate`` [Hz].

    Raises
    ------
    ValueError
        Unknown name (the message lists the valid ones).
    """
    if name not in PLAYBACKS:
        raise ValueError(f"unknown playback {name!r}; valid: {', '.join(PLAYBACKS)}")
    method, causal = PLAYBACKS[name]
    return Upsample(float(rate), method, causal)


class UpsampledSamples:
    """The sensor's raw samples resampled to ``upsample.rate``, made block by block.

    Sample ``j`` is ``τ_j = t_0 + j / rate`` with ``z(τ_j)`` and its arrival exactly as
    :meth:`rhmpc.sim.sensors.Upsample.apply` computes them for the whole stream (linear or hold,
    causal or not), arrivals made non-decreasing by a running maximum carried from block to block.
    Memory: the raw stream (≈ 8× smaller than the upsampled one at 257 Hz → 2 kHz).
    """

    def __init__(self, raw, upsample) -> None:
        self.raw_t = np.asarray(raw.t, dtype=float)
        self.raw_z = np.asarray(raw.z, dtype=float).reshape(self.raw_t.size, -1)
        self.raw_arrival = np.asarray(raw.arrival, dtype=float)
        if self.raw_t.size < 2:
            raise ValueError("upsampling needs at least two raw samples")
        self.rate, self.method, self.causal = float(upsample.rate), upsample.method, upsample.causal
        t_raw = self.raw_t
        self._n = int(np.floor((t_raw[-1] - t_raw[0]) * self.rate + 1e-9)) + 1
        self._carry = {0: -math.inf}  # running max of the arrivals before sample j, by j

    def __len__(self) -> int:
        return self._n

    @property
    def recorded(self) -> ArraySamples:
        """The raw samples (as recorded, before the delivery to the control rate)."""
        return ArraySamples(self.raw_t, self.raw_z, self.raw_arrival)

    def index_at(self, t: float) -> int:
        return grid_index(t, float(self.raw_t[0]), self.rate, self._n)

    def _samples(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        tau = self.raw_t[0] + np.arange(a, b) / self.rate
        return deliver(self.raw_t, self.raw_z, self.raw_arrival, tau, self.method, self.causal)

    def _carry_before(self, a: int) -> float:
        """max(arrival_0 … arrival_{a−1}) (−inf for a = 0), from the nearest known point."""
        start = max(j for j in self._carry if j <= a)
        carry = self._carry[start]
        while start < a:
            stop = min(start + BLOCK, a)
            carry = max(carry, float(self._samples(start, stop)[2].max()))
            start = stop
            if start % BLOCK == 0:
                self._carry[start] = carry
        return carry

    def block(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        a, b = max(a, 0), min(b, self._n)
        tau, z, arrival = self._samples(a, b)
        if b > a:
            arrival[0] = max(arrival[0], self._carry_before(a))
            np.maximum.accumulate(arrival, out=arrival)
            if b % BLOCK == 0 and b not in self._carry:
                self._carry[b] = float(arrival[-1])
        return tau, z, arrival


def sensor_samples(sensor, source, duration: float, rng: np.random.Generator):
    """``sensor.measure(source, duration, rng)`` as a sample source read in blocks.

    Same samples, same random draws: a trailing :class:`~rhmpc.sim.sensors.Upsample` stage (the
    2-kHz playback) runs block by block on the raw samples (:class:`UpsampledSamples`), a
    sensor without stages samples the source block by block (:class:`SampledSamples`), other
    sensors are measured whole.
    """
    if not sensor.stages:
        return SampledSamples(source, sensor.rate, sensor.sample_times(duration).size)
    if isinstance(sensor.stages[-1], Upsample):
        raw = replace(sensor, stages=sensor.stages[:-1]).measure(source, duration, rng)
        if len(raw) >= 2:
            return UpsampledSamples(raw, sensor.stages[-1])
        return ArraySamples.of(sensor.stages[-1].apply(raw, rng))
    return ArraySamples.of(sensor.measure(source, duration, rng))
