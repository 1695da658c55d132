"""The additive white Gaussian noise model of a position sensor (the ``white`` sensor).

    z_k = p(t_k) + n_k + o_k,   n_k ~ N(0, σ² I),   o_k the echo outliers,

as the 28-Hz prediction studies of Yuen et al. (2009) and Tuna et al. (2013 §VIII-C) corrupt
their data. For sonomicrometry the physical model of :mod:`rhmpc.sim.sensors.sonomicrometry` is the
default; this one serves those studies and noise sweeps.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from rhmpc.sim.sensors.events import Dropouts, EchoOutliers
from rhmpc.sim.sensors.playback import Upsample
from rhmpc.sim.sensors.stream import SampleStream, Sensor, delivery_stages


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
class WhiteSettings:
    """White-noise position sensor (the sonomicrometer as additive noise).

    Attributes
    ----------
    rate : float
        Sample rate [Hz] (Tuna et al. §III-A: 257 or 404).
    accuracy : float
        RMS of the 3-D error vector [m]; σ per axis = accuracy/√dim (250 µm, the
        sonomicrometer's absolute accuracy read as noise: 0.25 mm / √3 per axis in 3-D).
    outliers : EchoOutliers or None
        Echo outliers; None disables them.
    dropouts : Dropouts or None
        Occlusions (none by default).
    latency : float
        Delivery delay [s].
    upsample : Upsample or None
        Delivery to the control rate (:mod:`rhmpc.sim.sensors.playback`).
    """

    rate: float = 257.0
    accuracy: float = 0.25e-3
    outliers: EchoOutliers | None = field(default_factory=EchoOutliers)
    dropouts: Dropouts | None = None
    latency: float = 0.0
    upsample: Upsample | None = None


def white(settings: WhiteSettings | None = None, dim: int = 3) -> Sensor:
    """White-noise sensor: sample, white noise, echo outliers, dropouts, latency, upsample."""
    cfg = settings or WhiteSettings()
    stages: list = [WhiteNoise.from_accuracy(cfg.accuracy, dim)]
    if cfg.outliers is not None:
        stages.append(cfg.outliers)
    return Sensor(cfg.rate, (*stages, *delivery_stages(cfg)), "white")
