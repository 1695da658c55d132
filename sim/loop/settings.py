"""Timing and placement of a closed-loop run."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: When the predictor runs (:attr:`LoopSettings.predictor_clock`).
PREDICTOR_CLOCKS: tuple[str, ...] = ("auto", "downsample", "sensor")


@dataclass(frozen=True)
class LoopSettings:
    """Timing and placement of a closed-loop run.

    Attributes
    ----------
    Ts : float
        Control period [s] (2 kHz in the paper).
    horizon : int
        N, reference points per tick [ticks] (50 = 25 ms).
    downsample : int
        Ticks between predictor updates when the sensor is faster than the predictor (15 →
        7.5 ms, Tuna et al. Fig. 9: their 257-Hz sonomicrometer, read on the 2-kHz stream).
    predictor_clock : str
        When the predictor runs. ``"downsample"``: every ``downsample`` ticks on the newest
        sample delivered to the control rate (Tuna et al.'s protocol). ``"sensor"``: once per raw
        sample, at its arrival, stamped with its own measurement time, at the sensor's rate —
        the forecast then spans the delivery latency and the horizon (Yuen et al. 2009's delay
        compensation: predict across the latency rather than interpolate behind it).
        ``"auto"`` (default): ``"sensor"`` when the sensor's samples come more slowly than every
        ``downsample`` ticks (video at 25–30 Hz, 3-D ultrasound at 20–28 Hz, a tracker at
        40–100 Hz), else ``"downsample"``.
    prediction_points : int
        Points the predictor forecasts per update, before latency compensation (4).
    outlier_gate : float or str
        A sensor sample farther from its one-step forecast than max(floor, 4 × the running RMS
        forecast miss) is treated as missing (echo outliers: the heart cannot jump millimetres
        between two samples). ``"auto"`` (default): the floor is 4 × the RMS one-step miss of
        the predictor on the data themselves, measured over ``gate_calibration`` seconds after
        as many seconds of convergence (misses beyond 5 × their median left out, so that an
        outlier in that window does not widen the gate); every sample is accepted until then.
        It follows the sensor: the sonomicrometer's white range error and a video track's
        pixel noise give floors several times apart; the run reports the floor it found. A
        number: that floor [m]; 0 disables the gate. The choice is recorded in the design
        decisions (outlier gate).
    gate_calibration : float
        Length of the ``"auto"`` gate's convergence and of its calibration, each, in the
        predictor's own forecasts [s] (5 s: several beats; the two fit in the settling of a
        default run).
    outlier_max_rejections : int
        After this many consecutive rejected samples the gate opens (a real jump, or a forecast
        gone wrong) until 20 samples in a row fall inside it again [samples]. Default 3: a slip
        lasts up to 8 ms and the causal playback adds one raw period (3.9 ms at 257 Hz), so it
        reaches ⌈11.9 / 7.5⌉ + 1 = 3 samples of the predictor.
    guard_speed : float
        Reference guard: forecasts farther from the last accepted sample than ``guard_margin +
        guard_speed · lead`` mean a diverged predictor; the reference then holds that sample and
        the predictor restarts. Above the fastest POI motion of the replicas (0.21 m/s); 0
        disables [m/s].
    guard_margin : float
        Constant part of the guard's reach [m].
    duration : float
        Simulated time [s].
    settling : float
        Initial time excluded from the metrics while the predictors converge [s].
    poi_offset : tuple[float, float, float]
        Mean POI position relative to the end-effector's home position [m].
    pipelined_refresh : bool
        Spread each predictor refresh over four ticks, so that no tick carries all of it: the
        outlier gate and the predictor's update with the newest sample arrived by then, the
        predictor's learning (where it defers it), its forecast, and on the refresh tick the
        interpolation, guard and placement. False: the whole refresh on the refresh tick, with
        the newest sample arrived by that tick.
    compiled_ticks : bool
        Run the control ticks between two refresh slices in one C call where the controller
        and the robot's side are both compiled (``--controller c`` on the native plant): the
        same functions in the same order, hence the same results, without the interpreter
        between them, as in a deployed controller. False: one tick at a time from Python, as
        with the Python controller.
    compiled_refresh : bool
        Run the predictor's refresh (the outlier gate, the predictor, the interpolation, the
        guard and the placement) in C where it has a compiled twin (the one-step and the
        generalized RLS predictors with a known unit,
        :mod:`rhmpc.control.compiled_reference`) and a C compiler is found: the same
        equations in the same order, equal to the Python pipeline to rounding. False: the
        Python pipeline, the reference of the compiled one.
    """

    Ts: float = 0.5e-3
    horizon: int = 50
    downsample: int = 15
    predictor_clock: str = "auto"
    prediction_points: int = 4
    outlier_gate: float | str = "auto"
    gate_calibration: float = 5.0
    outlier_max_rejections: int = 3
    guard_speed: float = 0.3
    guard_margin: float = 2e-3
    duration: float = 20.0
    settling: float = 5.0
    poi_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    pipelined_refresh: bool = True
    compiled_ticks: bool = True
    compiled_refresh: bool = True

    def __post_init__(self) -> None:
        if not (np.isfinite(self.Ts) and self.Ts > 0):
            raise ValueError(f"Ts must be > 0 [s], got {self.Ts!r}")
        for name in ("horizon", "downsample", "prediction_points"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if self.predictor_clock not in PREDICTOR_CLOCKS:
            raise ValueError(f"predictor_clock must be one of {', '.join(PREDICTOR_CLOCKS)}, "
                             f"got {self.predictor_clock!r}")
        gate = self.outlier_gate
        if gate != "auto" and not (isinstance(gate, int | float) and np.isfinite(gate)
                                   and gate >= 0):
            raise ValueError(f"outlier_gate must be 'auto' or a number >= 0 [m], got {gate!r}")
        if not (np.isfinite(self.gate_calibration) and self.gate_calibration > 0):
            raise ValueError(f"gate_calibration must be > 0 [s], got {self.gate_calibration!r}")
        if not isinstance(self.outlier_max_rejections, int) or self.outlier_max_rejections < 0:
            raise ValueError(
                f"outlier_max_rejections must be an integer >= 0, got "
                f"{self.outlier_max_rejections!r}"
            )
        if not (np.isfinite(self.guard_speed) and self.guard_speed >= 0):
            raise ValueError(f"guard_speed must be >= 0 [m/s], got {self.guard_speed!r}")
        if not (np.isfinite(self.guard_margin) and self.guard_margin > 0):
            raise ValueError(f"guard_margin must be > 0 [m], got {self.guard_margin!r}")
        if self.prediction_points < 2:
            raise ValueError("prediction_points must be >= 2 (quadratic interpolation)")
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"duration must be > 0 [s], got {self.duration!r}")
        if not (0 <= self.settling < self.duration):
            raise ValueError(
                f"settling must be in [0, duration) [s], got {self.settling!r} "
                f"with duration {self.duration!r}"
            )
        if len(self.poi_offset) != 3 or not np.all(np.isfinite(self.poi_offset)):
            raise ValueError(f"poi_offset must be 3 finite numbers [m], got {self.poi_offset!r}")

    @property
    def ticks(self) -> int:
        return round(self.duration / self.Ts)

    @property
    def settling_ticks(self) -> int:
        return round(self.settling / self.Ts)

    @property
    def gate_floor(self) -> float | None:
        """The outlier gate's fixed floor [m], or None for one derived from the data."""
        return None if self.outlier_gate == "auto" else float(self.outlier_gate)
