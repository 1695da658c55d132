"""3-D ultrasound tracking (Yuen et al. 2009): a slow, noisy and late position sensor."""

from __future__ import annotations

from dataclasses import dataclass

from rhmpc.sim.sensors.events import Dropouts
from rhmpc.sim.sensors.stream import Latency, Sensor
from rhmpc.sim.sensors.white import WhiteNoise


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


def ultrasound(settings: UltrasoundSettings | None = None) -> Sensor:
    """3-D ultrasound sensor: sample at 28 Hz, σ = 1.3 mm noise, dropouts, 68 ms latency."""
    cfg = settings or UltrasoundSettings()
    stages: list = [WhiteNoise(cfg.noise_std)]
    if cfg.dropouts is not None:
        stages.append(cfg.dropouts)
    stages.append(Latency(cfg.latency))
    return Sensor(cfg.rate, tuple(stages), "ultrasound")
