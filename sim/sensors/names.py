"""Sensors by name, as the command line and a run's ``sensor_settings`` give them."""

from __future__ import annotations

from dataclasses import fields, replace

from rhmpc.sim.sensors.crystals import CrystalArray
from rhmpc.sim.sensors.events import Dropouts
from rhmpc.sim.sensors.playback import PLAYBACKS, playback
from rhmpc.sim.sensors.sonomicrometry import SonomicrometrySettings, sonomicrometry
from rhmpc.sim.sensors.stream import Latency, Sensor
from rhmpc.sim.sensors.ultrasound import UltrasoundSettings, ultrasound
from rhmpc.sim.sensors.video import VideoSettings, video
from rhmpc.sim.sensors.white import WhiteSettings, white

#: The default playback of a sensor's samples to the control rate (causal: linear
#: interpolation delivered one raw period late, every sample equally old).
DEFAULT_PLAYBACK = "linear"

#: Physical settings of ``sonomicrometry`` given by keyword: SonomicrometrySettings fields and,
#: for the crystals, ``crystals`` (the count), ``diameter``, ``standoff`` and ``angles``.
_CRYSTAL_KEYS = {"crystals": "count", "diameter": "diameter", "standoff": "standoff",
                 "angles": "angles"}
_PHYSICS_KEYS = {f.name for f in fields(SonomicrometrySettings)} - {
    "rate", "crystals", "dropouts", "latency", "upsample"}


def ideal(rate: float = 2000.0) -> Sensor:
    """Noise-free, delay-free samples of the truth at ``rate`` [Hz]."""
    return Sensor(rate, (), "ideal")


def _physics(physics: dict) -> dict:
    """SonomicrometrySettings keywords from the flat ``physics`` keywords."""
    unknown = sorted(set(physics) - _PHYSICS_KEYS - set(_CRYSTAL_KEYS))
    if unknown:
        valid = sorted(_PHYSICS_KEYS | set(_CRYSTAL_KEYS))
        raise TypeError(f"unknown setting(s) {', '.join(unknown)}; valid: {', '.join(valid)}")
    crystal = {_CRYSTAL_KEYS[k]: v for k, v in physics.items() if k in _CRYSTAL_KEYS}
    out = {k: v for k, v in physics.items() if k in _PHYSICS_KEYS}
    if "angles" in crystal:
        crystal["angles"] = tuple(float(a) for a in crystal["angles"])
    if "slip_duration" in out:
        out["slip_duration"] = tuple(float(v) for v in out["slip_duration"])
    if crystal:
        out["crystals"] = CrystalArray(**crystal)
    return out


def sensor_from_name(name: str, rate: float | None = None, latency: float | None = None,
                     noise: float | None = None, dropouts: Dropouts | None = None,
                     outliers: bool = True, upsample: float | None = None,
                     playback: str = DEFAULT_PLAYBACK, dim: int = 3, **physics) -> Sensor:
    """Build a sensor from a CLI-style name.

    Parameters
    ----------
    name : str
        ``"sonomicrometry"`` (physical, :mod:`rhmpc.sim.sensors.sonomicrometry`), ``"white"``
        (additive white noise, :mod:`rhmpc.sim.sensors.white`), ``"ultrasound"`` or ``"ideal"``.
    rate : float, optional
        Sample rate [Hz] (defaults: 257, 257, 28, 25, 2000).
    latency : float, optional
        Delay [s] (defaults: 0, 0, 0.068, 0.04, 0).
    noise : float, optional
        σ per axis [m] of ``white`` (default 0.25 mm/√dim), ``ultrasound`` (1.3 mm) or
        ``video`` (0.15 mm); the
        physical sonomicrometer has no such setting (its errors come from its physics).
    dropouts : Dropouts, optional
        Add occlusions.
    outliers : bool
        Echo outliers (cycle slips of ``sonomicrometry``) on/off.
    upsample : float, optional
        Deliver to this rate [Hz] with ``playback``.
    playback : str
        ``"linear"`` (causal, default), ``"hold"`` (causal) or ``"offline"`` (the non-causal
        playback of a prerecorded file), :data:`rhmpc.sim.sensors.playback.PLAYBACKS`.
    dim : int
        Axes of the source.
    **physics
        ``sonomicrometry`` only: fields of :class:`SonomicrometrySettings` (``sound_speed``,
        ``sound_speed_error``, ``clock``, ``frequency``, ``orientation_error``, ``tilt_lever``,
        ``slip_rate``, ``slip_duration``) and of its crystals (``crystals`` = the count,
        ``diameter``, ``standoff``, ``angles``), SI units.

    Raises
    ------
    ValueError
        Unknown name or playback (the message lists the valid ones), or an invalid setting.
    TypeError
        A setting the sensor does not have.
    """
    if playback not in PLAYBACKS:
        raise ValueError(f"unknown playback {playback!r}; valid: {', '.join(PLAYBACKS)}")
    build = _BUILDERS.get(name)
    if build is None:
        raise ValueError(f"unknown sensor {name!r}; valid names: {', '.join(SENSORS)}")
    if physics and name != "sonomicrometry":
        raise TypeError(f"sensor {name!r} has no setting(s) {', '.join(sorted(physics))}")
    timing = {key: float(value) for key, value in (("rate", rate), ("latency", latency))
              if value is not None}
    delivery = None if upsample is None else _playback(upsample, playback)
    return build(timing, noise, dropouts, outliers, delivery, dim, physics)


def _sonomicrometer(timing: dict, noise, dropouts, outliers: bool, delivery, dim: int,
                    physics: dict) -> Sensor:
    if noise is not None:
        raise TypeError("sonomicrometry has no 'noise' setting: its errors come from its "
                        "physics (use the 'white' sensor for additive noise)")
    kw: dict = {"dropouts": dropouts, "upsample": delivery, **_physics(physics), **timing}
    if not outliers:
        kw["slip_rate"] = 0.0
    return sonomicrometry(SonomicrometrySettings(**kw), dim)


def _white(timing: dict, noise, dropouts, outliers: bool, delivery, dim: int,
           physics: dict) -> Sensor:
    kw: dict = {"dropouts": dropouts, "upsample": delivery, **timing}
    if noise is not None:
        kw["accuracy"] = float(noise) * dim**0.5
    if not outliers:
        kw["outliers"] = None
    return white(replace(WhiteSettings(), **kw), dim)


def _ultrasound(timing: dict, noise, dropouts, outliers: bool, delivery, dim: int,
                physics: dict) -> Sensor:
    kw: dict = dict(timing)
    if noise is not None:
        kw["noise_std"] = float(noise)
    sensor = ultrasound(replace(UltrasoundSettings(dropouts=dropouts), **kw))
    return sensor.with_stages(delivery) if delivery is not None else sensor


def _video(timing: dict, noise, dropouts, outliers: bool, delivery, dim: int,
           physics: dict) -> Sensor:
    kw: dict = {"dropouts": dropouts, "upsample": delivery, **timing}
    if noise is not None:
        kw["noise_std"] = float(noise)
    return video(VideoSettings(**kw))


def _ideal(timing: dict, noise, dropouts, outliers: bool, delivery, dim: int,
           physics: dict) -> Sensor:
    stages: tuple = ()
    if dropouts is not None:
        stages += (dropouts,)
    if timing.get("latency"):
        stages += (Latency(timing["latency"]),)
    if delivery is not None and "rate" in timing:
        stages += (delivery,)
    return Sensor(timing.get("rate", 2000.0), stages, "ideal")


#: Each sensor name's builder: (timing, noise, dropouts, outliers, delivery, dim, physics).
_BUILDERS = {"sonomicrometry": _sonomicrometer, "white": _white, "ultrasound": _ultrasound,
             "video": _video, "ideal": _ideal}
#: Names :func:`sensor_from_name` accepts.
SENSORS: tuple[str, ...] = tuple(_BUILDERS)


def _playback(rate: float, name: str):
    return playback(name, float(rate))
