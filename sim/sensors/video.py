"""Stereo-endoscopic video tracking of a point on the heart: 25 frames/s, frame-to-frame noise.

    z_k = p(t_k) + n_k,   n_k ~ N(0, σ² I),   t_k = k/25 s,   delivered one frame late,

the sensor of the ``invivo-video`` regime (:mod:`rhmpc.sim.heart.invivo`). σ is measured from the
in-vivo recording that regime was built from: its ``hold`` error one frame ahead (0.57 mm, 3-D)
exceeds that of the regime's motion (0.43 mm, the mean over seeds 1–10) by what white noise adds at
every lead, 2·3σ² in the square: σ = √((0.57² − 0.43²)/6) = 0.15 mm per axis.
"""

from __future__ import annotations

from dataclasses import dataclass

from rhmpc.sim.sensors.events import Dropouts
from rhmpc.sim.sensors.playback import Upsample
from rhmpc.sim.sensors.stream import Sensor, delivery_stages
from rhmpc.sim.sensors.white import WhiteNoise


@dataclass(frozen=True)
class VideoSettings:
    """Stereo video tracking (module docstring).

    Attributes
    ----------
    rate : float
        Frame rate [Hz] (the recording's 25 frames/s).
    noise_std : float
        σ per axis [m] (0.15 mm, measured as in the module docstring).
    latency : float
        Delivery delay [s]: one frame, acquired then tracked (an assumption).
    dropouts : Dropouts or None
        Tracking losses (occlusion by instruments, specular reflections); None: none.
    upsample : Upsample or None
        Delivery to the control rate (:mod:`rhmpc.sim.sensors.playback`).
    """

    rate: float = 25.0
    noise_std: float = 0.15e-3
    latency: float = 1.0 / 25.0
    dropouts: Dropouts | None = None
    upsample: Upsample | None = None


def video(settings: VideoSettings | None = None) -> Sensor:
    """Video tracking sensor: sample at 25 Hz, σ = 0.15 mm noise, dropouts, one frame late."""
    cfg = settings or VideoSettings()
    return Sensor(cfg.rate, (WhiteNoise(cfg.noise_std), *delivery_stages(cfg)), "video")
