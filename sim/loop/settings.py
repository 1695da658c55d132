"""Timing and placement of a closed-loop run."""

from __future__ import annotations

import math
from dataclasses import dataclass

#: When the predictor runs (:attr:`LoopSettings.predictor_clock`).
PREDICTOR_CLOCKS: tuple[str, ...] = ("auto", "downsample", "sensor")
#: Where the heart motion is placed in the robot's workspace (:attr:`LoopSettings.placement`).
PLACEMENTS: tuple[str, ...] = ("centred", "absolute")
#: The control periods a run accepts [s]: 0.1–10 ms (10 kHz to 100 Hz). The controller is
#: designed at the run's period (the arm is linearised and discretised at ``Ts``), but outside
#: this range a "2-kHz" MPC with a 25-ms horizon of N points no longer means what it says.
TS_RANGE: tuple[float, float] = (1e-4, 1e-2)
#: The longest run [s] (one day): memory is flat in run length, time is not.
MAX_DURATION = 86_400.0
#: The settling window of a run that does not set one: this, or a third of a shorter run [s].
DEFAULT_SETTLING = 10.0


@dataclass(frozen=True)
class LoopSettings:
    """Timing and placement of a closed-loop run (the ``[loop]`` table).

    Attributes
    ----------
    Ts : float
        Control period [s] (0.5 ms: 2 kHz in Tuna et al. 2013); within :data:`TS_RANGE`.
    downsample : int
        Ticks between predictor refreshes when the sensor is faster than the predictor (15 →
        7.5 ms, Tuna et al. Fig. 9: their 257-Hz sonomicrometer, read on the 2-kHz stream).
    predictor_clock : str
        When the reference refreshes. ``"downsample"``: every ``downsample`` ticks on the newest
        sample delivered to the control rate (Tuna et al.'s protocol). ``"sensor"``: once per
        raw sample, at its arrival, stamped with its own measurement time, at the sensor's rate
        — the forecast then spans the delivery latency and the horizon (Yuen et al. 2009's delay
        compensation: predict across the latency rather than interpolate behind it). ``"auto"``
        (default): ``"sensor"`` when the sensor's samples come more slowly than every
        ``downsample`` ticks (video at 25–30 Hz, 3-D ultrasound at 20–28 Hz, a tracker at
        40–100 Hz), else ``"downsample"``.
    duration : float
        Simulated time [s], at most :data:`MAX_DURATION`.
    settling : float or None
        Initial time excluded from the metrics while the predictors converge [s]; None (default):
        :data:`DEFAULT_SETTLING`, or a third of a run shorter than three times that.
    poi_offset : tuple[float, float, float]
        Where the motion sits relative to its placement's origin [m] (see ``placement``).
    placement : str
        ``"centred"`` (default): the motion's mean over the run sits at the end-effector's home
        position plus ``poi_offset`` (a recording is re-centred: its absolute coordinates are
        those of its sensor, not the robot's). ``"absolute"``: the motion's own coordinates are
        the robot's world frame, shifted by ``poi_offset``.
    """

    Ts: float = 0.5e-3
    downsample: int = 15
    predictor_clock: str = "auto"
    duration: float = 30.0
    settling: float | None = None
    poi_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    placement: str = "centred"

    def __post_init__(self) -> None:
        lo, hi = TS_RANGE
        if not (_number(self.Ts) and lo <= self.Ts <= hi):
            raise ValueError(f"Ts must be between {lo:g} and {hi:g} s, got {self.Ts!r}")
        if isinstance(self.downsample, bool) or not isinstance(self.downsample, int) \
                or not 1 <= self.downsample <= 1000:
            raise ValueError(f"downsample must be an integer in 1 … 1000 [ticks], "
                             f"got {self.downsample!r}")
        if self.predictor_clock not in PREDICTOR_CLOCKS:
            raise ValueError(f"predictor_clock must be one of {', '.join(PREDICTOR_CLOCKS)}, "
                             f"got {self.predictor_clock!r}")
        if not (_number(self.duration) and 0 < self.duration <= MAX_DURATION):
            raise ValueError(f"duration must be > 0 and at most {MAX_DURATION:g} s, "
                             f"got {self.duration!r}")
        if self.settling is not None and not (_number(self.settling)
                                              and 0 <= self.settling < self.duration):
            raise ValueError(f"settling must be in [0, duration) [s], got {self.settling!r} "
                             f"with duration {self.duration!r}")
        offset = self.poi_offset
        if not (isinstance(offset, tuple | list) and len(offset) == 3
                and all(_number(v) for v in offset)):
            raise ValueError(f"poi_offset must be 3 finite numbers [m], got {offset!r}")
        if self.placement not in PLACEMENTS:
            raise ValueError(f"placement must be one of {', '.join(PLACEMENTS)}, "
                             f"got {self.placement!r}")

    @property
    def settling_s(self) -> float:
        """The settling window [s]: ``settling``, or its default for this duration."""
        if self.settling is not None:
            return float(self.settling)
        return min(DEFAULT_SETTLING, self.duration / 3)

    @property
    def ticks(self) -> int:
        return round(self.duration / self.Ts)

    @property
    def settling_ticks(self) -> int:
        return round(self.settling_s / self.Ts)


def _number(value) -> bool:
    """A finite int or float (not a bool)."""
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)

