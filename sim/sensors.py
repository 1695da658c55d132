"""Sensor models: sampling, noise, echo outliers, dropouts, latency, encoder quantisation.

A :class:`Sensor` samples the truth of a motion source at its rate and passes the samples
through a chain of stages, each a frozen settings dataclass with ``apply(stream, rng)``:

    z_k = p(t_k) + n_k + o_k,   n_k ~ N(0, σ² I),   o_k the echo outliers,
    z_k = NaN during dropouts,  arrival_k = t_k + latency.

The models of the papers are ready-made: :func:`sonomicrometry` (Tuna et al. §III-A: 257 or
404 Hz, 0.25 mm accuracy, echo outliers, optional interpolation to the 2 kHz control stream)
and :func:`ultrasound` (Yuen et al.: 3-D ultrasound at 28 Hz, σ = 1.3 mm, 68 ms latency).
:class:`Encoder` quantises joint angles. All randomness comes from the injected
``numpy.random.Generator``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from sim.motion import MotionSource


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
class WhiteNoise:
    """Additive white Gaussian noise z_k ← z_k + n_k, n_k ~ N(0, σ² I).

    Attributes
    ----------
    std : float
        σ per axis [m].
    """

    std: float

    def __post_init__(self) -> None:
        if not self.std >= 0:
            raise ValueError("noise std must be ≥ 0 [m]")

    def apply(self, stream: SampleStream, rng: np.random.Generator) -> SampleStream:
        noise = self.std * rng.standard_normal(stream.z.shape)
        return replace(stream, z=stream.z + noise)

    @classmethod
    def from_accuracy(cls, accuracy: float, dim: int) -> WhiteNoise:
        """σ = accuracy/√dim, so that the RMS of the error vector is ``accuracy`` [m]."""
        return cls(accuracy / np.sqrt(dim))


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
class Upsample:
    """Resample the stream to a faster rate, as the paper's streamed playback to 2 kHz.

    ``"linear"``: z(τ_j) = z_k + (τ_j − t_k)/(t_{k+1} − t_k)·(z_{k+1} − z_k), NaN if either
    neighbour is missing; ``"hold"``: z(τ_j) = z_k (zero-order hold). With ``causal`` the
    interpolated sample arrives when its newer neighbour has (arrival(t_{k+1})); without, it
    arrives at τ_j + (arrival_k − t_k), as when a prerecorded file is played back.

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
        t_raw, z_raw = stream.t, stream.z
        if t_raw.size < 2:
            return stream
        n = int(np.floor((t_raw[-1] - t_raw[0]) * self.rate + 1e-9)) + 1
        tau = t_raw[0] + np.arange(n) / self.rate
        k = np.clip(np.searchsorted(t_raw, tau, side="right") - 1, 0, t_raw.size - 2)
        delay = stream.arrival - stream.t
        if self.method == "hold":
            held = np.clip(np.searchsorted(t_raw, tau + 1e-12, side="right") - 1, 0,
                           t_raw.size - 1)
            z = z_raw[held].copy()
            arrival = tau + delay[held]
        else:
            w = ((tau - t_raw[k]) / (t_raw[k + 1] - t_raw[k]))[:, None]
            with np.errstate(invalid="ignore"):
                z = (1.0 - w) * z_raw[k] + w * z_raw[k + 1]
            exact0 = w[:, 0] == 0.0
            z[exact0] = z_raw[k][exact0]
            if self.causal:
                arrival = np.where(exact0, stream.arrival[k], stream.arrival[k + 1])
            else:
                arrival = tau + delay[k]
        return SampleStream(tau, z, np.maximum.accumulate(arrival), self.rate)


@dataclass(frozen=True)
class Sensor:
    """A sampler followed by processing stages.

    Sampling: t_k = t₀ + k/rate for k = 0 … ⌊duration·rate⌋, z_k = p(t_k), arrival_k = t_k;
    then each stage in order.

    Attributes
    ----------
    rate : float
        Sample rate [Hz].
    stages : tuple
        Processing stages (:class:`WhiteNoise`, :class:`EchoOutliers`, :class:`Dropouts`,
        :class:`Latency`, :class:`Upsample`, or anything with ``apply(stream, rng)``).
    name : str
        Label for reports.
    """

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
        z = np.asarray(source.position(t), dtype=float).reshape(t.size, -1)
        stream = SampleStream(t, z, t.copy(), self.rate)
        for stage in self.stages:
            stream = stage.apply(stream, rng)
        return stream

    def with_stages(self, *extra: Stage) -> Sensor:
        """A copy with ``extra`` stages appended."""
        return replace(self, stages=self.stages + tuple(extra))


@dataclass(frozen=True)
class SonomicrometrySettings:
    """Sonomicrometry (Sonometrics; Tuna et al. §III-A).

    Attributes
    ----------
    rate : float
        Sample rate [Hz]: 257 or 404 in the paper (the device can reach 2 kHz).
    accuracy : float
        RMS of the 3-D error vector [m]; σ per axis = accuracy/√dim (250 µm: ~¼ wavelength).
    outliers : EchoOutliers or None
        Echo outliers; None disables them.
    dropouts : Dropouts or None
        Occlusions (none by default: the balloon keeps a line of sight).
    latency : float
        Delivery delay [s].
    upsample : Upsample or None
        Resample to the control rate, e.g. ``Upsample(2000.0)`` as the paper's playback.
    """

    rate: float = 257.0
    accuracy: float = 0.25e-3
    outliers: EchoOutliers | None = field(default_factory=EchoOutliers)
    dropouts: Dropouts | None = None
    latency: float = 0.0
    upsample: Upsample | None = None


@dataclass(frozen=True)
class UltrasoundSettings:
    """3-D ultrasound tracking (Yuen et al. 2009 §5–6).

    Attributes
    ----------
    rate : float
        Volume rate [Hz] (24–28 Hz; 28 typical in vivo).
    noise_std : float
        σ per axis [m] (1.3 mm measured for the annulus estimates).
    latency : float
        Imaging plus segmentation delay [s] (68 ms; experiments used 39–132 ms).
    dropouts : Dropouts or None
        Tracking losses; None disables them.
    """

    rate: float = 28.0
    noise_std: float = 1.3e-3
    latency: float = 0.068
    dropouts: Dropouts | None = None


def sonomicrometry(settings: SonomicrometrySettings | None = None, dim: int = 3) -> Sensor:
    """Sonomicrometry sensor: sample, white noise, echo outliers, dropouts, latency, upsample."""
    cfg = settings or SonomicrometrySettings()
    stages: list = [WhiteNoise.from_accuracy(cfg.accuracy, dim)]
    if cfg.outliers is not None:
        stages.append(cfg.outliers)
    if cfg.dropouts is not None:
        stages.append(cfg.dropouts)
    if cfg.latency:
        stages.append(Latency(cfg.latency))
    if cfg.upsample is not None:
        stages.append(cfg.upsample)
    return Sensor(cfg.rate, tuple(stages), "sonomicrometry")


def ultrasound(settings: UltrasoundSettings | None = None) -> Sensor:
    """3-D ultrasound sensor: sample at 28 Hz, σ = 1.3 mm noise, dropouts, 68 ms latency."""
    cfg = settings or UltrasoundSettings()
    stages: list = [WhiteNoise(cfg.noise_std)]
    if cfg.dropouts is not None:
        stages.append(cfg.dropouts)
    stages.append(Latency(cfg.latency))
    return Sensor(cfg.rate, tuple(stages), "ultrasound")


def ideal(rate: float = 2000.0) -> Sensor:
    """Noise-free, delay-free samples of the truth at ``rate`` [Hz]."""
    return Sensor(rate, (), "ideal")


#: Names :func:`sensor_from_name` accepts.
SENSORS: tuple[str, ...] = ("sonomicrometry", "ultrasound", "ideal")


def sensor_from_name(name: str, rate: float | None = None, latency: float | None = None,
                     noise: float | None = None, dropouts: Dropouts | None = None,
                     outliers: bool = True, upsample: float | None = None,
                     dim: int = 3) -> Sensor:
    """Build a sensor from a CLI-style name.

    Parameters
    ----------
    name : str
        ``"sonomicrometry"``, ``"ultrasound"`` or ``"ideal"``.
    rate : float, optional
        Sample rate [Hz] (defaults: 257, 28, 2000).
    latency : float, optional
        Delay [s] (defaults: 0, 0.068, 0).
    noise : float, optional
        Sonomicrometry accuracy or ultrasound σ per axis [m].
    dropouts : Dropouts, optional
        Add occlusions.
    outliers : bool
        Sonomicrometry echo outliers on/off.
    upsample : float, optional
        Resample to this rate [Hz] (linear, playback-style).
    dim : int
        Axes of the source (sets σ = accuracy/√dim for sonomicrometry).

    Raises
    ------
    ValueError
        Unknown name (the message lists the valid ones).
    """
    if name == "sonomicrometry":
        cfg = SonomicrometrySettings(dropouts=dropouts)
        kw: dict = {}
        if rate is not None:
            kw["rate"] = float(rate)
        if latency is not None:
            kw["latency"] = float(latency)
        if noise is not None:
            kw["accuracy"] = float(noise)
        if not outliers:
            kw["outliers"] = None
        if upsample is not None:
            kw["upsample"] = Upsample(float(upsample))
        return sonomicrometry(replace(cfg, **kw), dim)
    if name == "ultrasound":
        cfg_us = UltrasoundSettings(dropouts=dropouts)
        kw = {}
        if rate is not None:
            kw["rate"] = float(rate)
        if latency is not None:
            kw["latency"] = float(latency)
        if noise is not None:
            kw["noise_std"] = float(noise)
        sensor = ultrasound(replace(cfg_us, **kw))
        return sensor.with_stages(Upsample(float(upsample))) if upsample else sensor
    if name == "ideal":
        stages: tuple = ()
        if dropouts is not None:
            stages += (dropouts,)
        if latency:
            stages += (Latency(float(latency)),)
        return Sensor(2000.0 if rate is None else float(rate), stages, "ideal")
    raise ValueError(f"unknown sensor {name!r}; valid names: {', '.join(SENSORS)}")


@dataclass(frozen=True)
class Encoder:
    """Incremental joint encoder: q̂ = Δ·round(q/Δ), Δ = 2π/counts_per_rev (or floor).

    Attributes
    ----------
    counts_per_rev : int
        Counts per revolution after quadrature decoding (4 × 1024 lines).
    mode : str
        ``"round"`` (error in ±Δ/2, unbiased) or ``"floor"`` (counter truncation, error in
        [0, Δ)).
    """

    counts_per_rev: int = 4 * 1024
    mode: str = "round"

    def __post_init__(self) -> None:
        if self.counts_per_rev <= 0:
            raise ValueError("counts_per_rev must be positive")
        if self.mode not in ("round", "floor"):
            raise ValueError("encoder mode must be 'round' or 'floor'")

    @property
    def resolution(self) -> float:
        """Δ = 2π / counts_per_rev [rad]."""
        return 2 * np.pi / self.counts_per_rev

    def counts(self, q: np.ndarray) -> np.ndarray:
        """Integer counts for joint angles ``q`` [rad]."""
        x = np.asarray(q, dtype=float) / self.resolution
        return (np.round(x) if self.mode == "round" else np.floor(x)).astype(np.int64)

    def quantize(self, q: float | np.ndarray) -> np.ndarray:
        """Quantised joint angles q̂ [rad], same shape as ``q``."""
        return self.counts(q) * self.resolution
