"""Chunked sample streams and POI truth: the open-loop inputs of a run in memory that does not grow.

A run of ``n`` ticks needs, at 2 kHz, the sensor samples the controller sees and the true POI
position at every tick. Held as arrays they cost ≈ 64 bytes per tick (0.9 GB for two hours), so
the loop reads them in blocks:

- a *sample source* has ``len()``, ``index_at(t)`` and ``block(a, b)`` → ``(t, z, arrival)`` of
  samples ``a … b − 1``: :class:`ArraySamples` wraps arrays already in memory,
  :class:`UpsampledSamples` makes the sensor's 2-kHz playback stream from its raw samples on
  demand (the same arithmetic as :class:`sim.sensors.Upsample`, identical to the last bit), and
  :class:`SampledSamples` samples a motion source on demand (a sensor without stages);
- :class:`StreamCursor` walks a sample source forward in time: the newest sample arrived by a
  given instant;
- a *truth* has ``center`` (the POI's mean over the run), ``n_ticks`` and ``window(i0, i1)``, the
  centred positions of ticks ``i0 … i1 − 1``: :class:`ArrayTruth` wraps an array,
  :class:`SourceTruth` evaluates a motion source per window (two passes: the mean, then the run).

Only the mean is not identical to the whole-array ``np.nanmean``: it is summed per block, which
changes its last bits (≤ 1e-19 m for millimetre motion, far below anything printed).
"""

from __future__ import annotations

import bisect
import math

import numpy as np

#: Samples per block read from a sample source (≈ 2 s of a 2-kHz stream).
BLOCK = 4096


def _grid_index(t: float, t0: float, rate: float, n: int) -> int:
    """Index of the last of the samples t₀ + j/rate (j = 0 … n − 1) at or before ``t`` (−1 if
    none), exact in floating point (the estimate from ⌊(t − t₀)·rate⌋ corrected either way)."""
    j = int(np.floor((t - t0) * rate))
    while j + 1 < n and t0 + (j + 1) / rate <= t:
        j += 1
    while j >= 0 and t0 + j / rate > t:
        j -= 1
    return min(j, n - 1)


class ArraySamples:
    """A sample source over arrays in memory: ``t`` (n,), ``z`` (n, d) and ``arrival`` (n,)."""

    def __init__(self, t: np.ndarray, z: np.ndarray, arrival: np.ndarray) -> None:
        self.t = np.asarray(t, dtype=float)
        self.z = np.asarray(z, dtype=float).reshape(self.t.size, -1)
        self.arrival = np.asarray(arrival, dtype=float)
        if self.arrival.shape != self.t.shape:
            raise ValueError("t and arrival must have the same length")

    @classmethod
    def of(cls, stream) -> ArraySamples:
        """Wrap anything with arrays ``t``, ``z`` and ``arrival`` (a ``SampleStream``)."""
        return cls(stream.t, stream.z, stream.arrival)

    def __len__(self) -> int:
        return int(self.t.size)

    def index_at(self, t: float) -> int:
        """Index of the last sample at or before ``t`` (−1 before the first)."""
        return int(np.searchsorted(self.t, t, side="right")) - 1

    def block(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.t[a:b], self.z[a:b], self.arrival[a:b]


class UpsampledSamples:
    """The sensor's raw samples resampled to ``upsample.rate``, made block by block.

    Sample ``j`` is ``τ_j = t_0 + j / rate`` with ``z(τ_j)`` and its arrival exactly as
    :meth:`sim.sensors.Upsample.apply` computes them for the whole stream (linear or hold, causal
    or not), arrivals made non-decreasing by a running maximum carried from block to block.
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
        return _grid_index(t, float(self.raw_t[0]), self.rate, self._n)

    def _samples(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        from sim.sensors.playback import deliver

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


class SampledSamples:
    """Samples ``t_k = t_0 + k / rate`` (k = 0 … n − 1) of a motion source, arriving at ``t_k``.

    The samples of a :class:`sim.sensors.Sensor` without stages, made block by block.
    """

    def __init__(self, source, rate: float, n: int, t0: float = 0.0) -> None:
        self.source, self.rate, self._n, self.t0 = source, float(rate), int(n), float(t0)

    def __len__(self) -> int:
        return self._n

    def index_at(self, t: float) -> int:
        return _grid_index(t, self.t0, self.rate, self._n)

    def block(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        a, b = max(a, 0), min(b, self._n)
        t = self.t0 + np.arange(a, b) / self.rate
        z = np.asarray(self.source.position(t), dtype=float).reshape(t.size, -1)
        return t, z, t.copy()


def measure(sensor, source, duration: float, rng: np.random.Generator,
            chunk: int = 65_536):
    """``sensor.measure(source, duration, rng)`` with the source sampled ``chunk`` samples at a
    time: the same samples, stages and random draws, without the whole-run temporaries of a
    motion model evaluated at every sample time at once (≈ 380 bytes per sample for the
    RR-driven replicas, 0.7 GB for two hours at 257 Hz).

    A motion model evaluated on a shorter array may differ in the last bit (numpy's vectorised
    transcendental functions): measured ≤ 1e-17 m.
    """
    from sim.sensors import SampleStream

    if not duration >= 0:
        raise ValueError("duration must be ≥ 0 [s]")
    t = sensor.sample_times(duration)
    parts = [np.asarray(source.position(t[a : a + chunk]), dtype=float).reshape(
        t[a : a + chunk].size, -1) for a in range(0, t.size, chunk)]
    z = np.concatenate(parts) if parts else np.empty((0, getattr(source, "dim", 1)))
    del parts
    stream = SampleStream(t, z, t.copy(), sensor.rate)
    for stage in sensor.stages:
        stream = stage.apply(stream, rng)
    return stream


def sensor_samples(sensor, source, duration: float, rng: np.random.Generator):
    """``sensor.measure(source, duration, rng)`` as a sample source read in blocks.

    Same samples, same random draws: a trailing :class:`~sim.sensors.Upsample` stage (the
    2-kHz playback) runs block by block on the raw samples (:class:`UpsampledSamples`), a
    sensor without stages samples the source block by block (:class:`SampledSamples`), other
    sensors are measured whole (with the motion sampled in chunks, :func:`measure`).
    """
    from dataclasses import replace

    from sim.sensors import Upsample

    if not sensor.stages:
        return SampledSamples(source, sensor.rate, sensor.sample_times(duration).size)
    if isinstance(sensor.stages[-1], Upsample):
        raw = measure(replace(sensor, stages=sensor.stages[:-1]), source, duration, rng)
        if len(raw) >= 2:
            return UpsampledSamples(raw, sensor.stages[-1])
        return ArraySamples.of(sensor.stages[-1].apply(raw, rng))
    return ArraySamples.of(measure(sensor, source, duration, rng))


def as_samples(stream):
    """A sample source: ``stream`` itself if it has ``block``, else its arrays wrapped."""
    return stream if hasattr(stream, "block") else ArraySamples.of(stream)


class StreamCursor:
    """The newest sample arrived by a time that only moves forward.

    ``newest(now)`` is ``searchsorted(arrival, now, "right") − 1`` over the whole stream (−1
    before the first arrival), read one :data:`BLOCK` at a time; ``sample(j)`` is ``(t_j, z_j)``
    for an index ``newest`` returned last.
    """

    def __init__(self, samples, block: int = BLOCK) -> None:
        self.samples, self.size, self.n = samples, block, len(samples)
        self._b = -1
        self._current = self._previous = None
        self._advance()

    def _advance(self) -> None:
        self._b += 1
        a = self._b * self.size
        self._previous = self._current
        self._current = self.samples.block(a, min(a + self.size, self.n))
        self._arrival = self._current[2].tolist()  # bisect on floats: no NumPy call a tick

    def newest(self, now: float) -> int:
        arrival = self._arrival
        while arrival and arrival[-1] <= now and (self._b + 1) * self.size < self.n:
            self._advance()
            arrival = self._arrival
        k = bisect.bisect_right(arrival, now) - 1  # searchsorted(…, "right") − 1
        return self._b * self.size + k  # k = −1: the previous block's last sample (or −1)

    def sample(self, j: int) -> tuple[float, np.ndarray]:
        k = j - self._b * self.size
        t, z, _ = self._current if k >= 0 else self._previous
        return float(t[k]), z[k]


class ArrayTruth:
    """Centred POI truth from an array of positions at ticks 0 … n − 1 (already centred)."""

    def __init__(self, truth: np.ndarray, center: np.ndarray) -> None:
        self.truth = np.asarray(truth, dtype=float)
        self.truth = self.truth.reshape(self.truth.shape[0], -1)
        self.center = np.asarray(center, dtype=float)
        self.n_ticks, self.dim = self.truth.shape

    def window(self, i0: int, i1: int) -> np.ndarray:
        return self.truth[i0:i1]


def measurements(z: np.ndarray) -> np.ndarray:
    """Samples (n, d) with every one that is no measurement (a non-finite component, or a
    squared norm that overflows: ‖z‖ > 1e154) set to NaN, as the predictors take them
    (:func:`predictors.base.is_measured`): no score is taken against them."""
    z = np.asarray(z, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        bad = ~np.isfinite(np.einsum("ij,ij->i", z, z))
    if not bad.any():
        return z
    z = z.copy()
    z[bad] = np.nan
    return z


class SourceTruth:
    """Centred POI truth ``p(i·Ts) − mean`` of a motion source, evaluated per window.

    The mean over ticks 0 … n_ticks − 1 (NaN ignored per axis) is made in a first pass of
    ``chunk`` ticks; ``centred=False`` keeps the motion's own coordinates (``center`` zero, the
    mean still checked for a finite sample). ``source`` may instead be a sample source
    (``ground_truth = "recorded"``): the truth is then the stream linearly interpolated at the
    tick times (:class:`sim.recordings.RecordedMotion` on the samples around each window), its
    samples that are no measurements missing (:func:`measurements`).
    """

    def __init__(self, source, n_ticks: int, Ts: float, chunk: int = 20_000,
                 centred: bool = True) -> None:
        self.source, self.n_ticks, self.Ts = source, int(n_ticks), float(Ts)
        #: indices of the recorded samples that are no measurements (missing for the truth)
        self.unmeasured: set[int] = set()
        total, count = None, None
        for i0 in range(0, self.n_ticks, chunk):
            p = self._raw(i0, min(i0 + chunk, self.n_ticks))
            finite = np.isfinite(p)
            s = np.where(finite, p, 0.0).sum(axis=0)
            total = s if total is None else total + s
            count = finite.sum(axis=0) if count is None else count + finite.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            self.center = total / count
        if not np.all(np.isfinite(self.center)):
            raise ValueError("the heart motion has no finite sample over the run")
        if not centred:
            self.center = np.zeros_like(self.center)
        self.dim = self.center.size

    def _raw(self, i0: int, i1: int) -> np.ndarray:
        t = np.arange(i0, i1) * self.Ts
        if hasattr(self.source, "block"):
            from sim.recordings import RecordedMotion

            a = max(self.source.index_at(t[0]) - 2, 0)
            b = min(self.source.index_at(t[-1]) + 3, len(self.source))
            ts, z, _ = self.source.block(a, b)
            z = measurements(z)
            self.unmeasured.update((a + np.flatnonzero(np.isnan(z).any(axis=1))).tolist())
            return RecordedMotion(ts, z, name="recorded stream").position(t)
        return np.asarray(self.source.position(t), dtype=float).reshape(t.size, -1)

    def window(self, i0: int, i1: int) -> np.ndarray:
        i1 = min(i1, self.n_ticks)
        return self._raw(i0, i1) - self.center


#: A sample source the loop reads block by block.
SampleSource = ArraySamples | UpsampledSamples | SampledSamples


class PointsAt:
    """The other tracked points of a recording, looked up by measurement time: what a
    multi-point predictor reads beside the POI's sample (:meth:`predictors.base.Predictor.update`).

    Parameters
    ----------
    t : ndarray (n,)
        The recording's sample times, in the run's time [s].
    others : ndarray (n, P − 1, d)
        The other points' positions at those times [m] (NaN where a point is missing).
    """

    #: Times closer than this to a sample's time count as that sample [s].
    SNAP = 1e-9

    def __init__(self, t: np.ndarray, others: np.ndarray) -> None:
        self.t = np.asarray(t, dtype=float)
        self.others = np.asarray(others, dtype=float)
        if self.others.ndim != 3 or self.others.shape[0] != self.t.size:
            raise ValueError(f"others must be (n, P - 1, d) with n = {self.t.size} samples, "
                             f"got {self.others.shape}")

    def centred(self, center: np.ndarray) -> PointsAt:
        """The same points less ``center`` [m] (the POI's placement)."""
        return PointsAt(self.t, self.others - np.asarray(center, dtype=float))

    def at(self, t: float) -> np.ndarray | None:
        """The (P − 1, d) positions measured at ``t`` [m], or None when no sample was."""
        i = int(np.searchsorted(self.t, t - self.SNAP))
        if i < self.t.size and abs(self.t[i] - t) <= self.SNAP:
            return self.others[i]
        return None
