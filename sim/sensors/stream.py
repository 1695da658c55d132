"""Sample streams, processing stages and the sampler every sensor starts from.

A :class:`Sensor` samples the truth of a motion source at its rate and passes the samples
through a chain of stages, each a frozen settings dataclass with ``apply(stream, rng)``::

    t_k = t_0 + k/rate,   z_k = p(t_k),   arrival_k = t_k   (then each stage in order).

A run reads the samples in blocks, so that its memory does not grow with its length (at 2 kHz a
stream held whole costs ≈ 64 bytes per tick): a *sample source* has ``len()``, ``index_at(t)``
and ``block(a, b)`` → ``(t, z, arrival)`` of samples ``a … b − 1``: :class:`ArraySamples` over
arrays in memory, :class:`SampledSamples` (a sensor without stages, sampled on demand) and
:class:`rhmpc.sim.sensors.playback.UpsampledSamples` (the delivery to the control rate, made on
demand).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import ClassVar, Protocol

import numpy as np

from rhmpc.sim.heart.motion import MotionSource


@dataclass(frozen=True)
class SampleStream:
    """Sensor samples as the controller sees them.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Times the samples describe [s].
    z : ndarray, shape (n, dim)
        Measured positions [m]; NaN for missing samples.
    arrival : ndarray, shape (n,)
        Times the samples become available to the controller [s] (t + latency), non-decreasing.
    rate : float
        Nominal sample rate [Hz].
    """

    t: np.ndarray
    z: np.ndarray
    arrival: np.ndarray
    rate: float

    @property
    def dim(self) -> int:
        """Number of axes."""
        return int(self.z.shape[1])

    def __len__(self) -> int:
        return int(self.t.size)

    def available(self, now: float | np.ndarray) -> np.ndarray:
        """Number of samples that have arrived by time ``now`` [s] (arrival ≤ now)."""
        return np.searchsorted(self.arrival, now, side="right")

    def latest(self, now: float) -> tuple[float, np.ndarray] | None:
        """(t, z) of the newest sample arrived by ``now``, or None if nothing has arrived."""
        k = int(self.available(now))
        return None if k == 0 else (float(self.t[k - 1]), self.z[k - 1])


class Stage(Protocol):
    """One processing step of a sensor: ``apply(stream, rng) -> stream``."""

    def apply(self, stream: SampleStream, rng: np.random.Generator) -> SampleStream: ...


@dataclass(frozen=True)
class Latency:
    """Delivery delay: arrival_k = t_k + delay.

    Attributes
    ----------
    delay : float
        Acquisition plus processing delay [s] (3-D ultrasound: 39–132 ms, Yuen et al. §5–6).
    """

    delay: float

    def __post_init__(self) -> None:
        if not self.delay >= 0:
            raise ValueError("latency must be ≥ 0 [s]")

    def apply(self, stream: SampleStream, rng: np.random.Generator) -> SampleStream:
        return replace(stream, arrival=stream.arrival + self.delay)


@dataclass(frozen=True)
class Sensor:
    r"""A sampler followed by processing stages.

    Sampling, then each stage in order:

    .. math::

        t_k = t_0 + \frac{k}{\text{rate}}, \quad
        k = 0, \dots, \lfloor \text{duration} \cdot \text{rate} \rfloor, \qquad
        z_k = p(t_k), \qquad \text{arrival}_k = t_k.

    Attributes
    ----------
    rate : float
        Sample rate [Hz].
    stages : tuple
        Processing stages (:class:`~rhmpc.sim.sensors.white.WhiteNoise`,
        :class:`~rhmpc.sim.sensors.events.EchoOutliers`,
        :class:`~rhmpc.sim.sensors.events.Dropouts`, :class:`Latency`,
        :class:`~rhmpc.sim.sensors.playback.Upsample`, or anything with ``apply(stream, rng)``).
    name : str
        Label for reports.
    """

    #: Samples of the source evaluated at once by :meth:`measure`.
    CHUNK: ClassVar[int] = 65_536

    rate: float
    stages: tuple = field(default=())
    name: str = "sensor"

    def __post_init__(self) -> None:
        if not self.rate > 0:
            raise ValueError("sensor rate must be > 0 [Hz]")

    @property
    def latency(self) -> float:
        """Total delay of the :class:`Latency` stages [s]."""
        return float(sum(s.delay for s in self.stages if isinstance(s, Latency)))

    def sample_times(self, duration: float, t0: float = 0.0) -> np.ndarray:
        """t_k = t₀ + k/rate, k = 0 … ⌊duration·rate⌋ [s] (integer counts, no accumulation)."""
        n = int(np.floor(duration * self.rate + 1e-9)) + 1
        return t0 + np.arange(n) / self.rate

    def measure(self, source: MotionSource, duration: float, rng: np.random.Generator,
                t0: float = 0.0) -> SampleStream:
        """Sample ``source`` over ``[t0, t0 + duration]`` and apply the stages.

        Parameters
        ----------
        source : MotionSource
            The truth, ``position(t)`` [m].
        duration : float
            Length [s].
        rng : numpy.random.Generator
            The only source of randomness.
        t0 : float
            First sample time [s].
        """
        if not duration >= 0:
            raise ValueError("duration must be ≥ 0 [s]")
        t = self.sample_times(duration, t0)
        # the source sampled CHUNK samples at a time: no whole-run temporaries of a motion model
        chunks = [np.asarray(source.position(t[a:a + self.CHUNK]), dtype=float).reshape(
            t[a:a + self.CHUNK].size, -1) for a in range(0, t.size, self.CHUNK)]
        z = np.concatenate(chunks) if chunks else np.empty((0, getattr(source, "dim", 1)))
        stream = SampleStream(t, z, t.copy(), self.rate)
        for stage in self.stages:
            stream = stage.apply(stream, rng)
        return stream

    def with_stages(self, *extra: Stage) -> Sensor:
        """A copy with ``extra`` stages appended."""
        return replace(self, stages=self.stages + tuple(extra))


def delivery_stages(cfg) -> tuple:
    """The stages after the measurement, in order: dropouts, latency, delivery to the control
    rate — from any sensor settings with ``dropouts``, ``latency`` [s] and ``upsample``."""
    stages: list = []
    if cfg.dropouts is not None:
        stages.append(cfg.dropouts)
    if cfg.latency:
        stages.append(Latency(cfg.latency))
    if cfg.upsample is not None:
        stages.append(cfg.upsample)
    return tuple(stages)


#: Samples per block read from a sample source (≈ 2 s of a 2-kHz stream).
BLOCK = 4096


def grid_index(t: float, t0: float, rate: float, n: int) -> int:
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


class SampledSamples:
    """Samples ``t_k = t_0 + k / rate`` (k = 0 … n − 1) of a motion source, arriving at ``t_k``.

    The samples of a :class:`rhmpc.sim.sensors.Sensor` without stages, made block by block.
    """

    def __init__(self, source, rate: float, n: int, t0: float = 0.0) -> None:
        self.source, self.rate, self._n, self.t0 = source, float(rate), int(n), float(t0)

    def __len__(self) -> int:
        return self._n

    def index_at(self, t: float) -> int:
        return grid_index(t, self.t0, self.rate, self._n)

    def block(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        a, b = max(a, 0), min(b, self._n)
        t = self.t0 + np.arange(a, b) / self.rate
        z = np.asarray(self.source.position(t), dtype=float).reshape(t.size, -1)
        return t, z, t.copy()


def as_samples(stream):
    """A sample source: ``stream`` itself if it has ``block``, else its arrays wrapped."""
    return stream if hasattr(stream, "block") else ArraySamples.of(stream)


class SampleSource(Protocol):
    """Samples read in blocks (the module docstring)."""

    def __len__(self) -> int: ...

    def index_at(self, t: float) -> int: ...

    def block(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
