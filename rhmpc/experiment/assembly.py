"""The assembly of a run's world: robot, controller, heart motion, sensor stream, reference.

This is where the packages meet: ``robots`` (model, linearisation), ``sim`` (heart motion,
sensor, plant, loop), ``predictors`` and the controller of :mod:`rhmpc.control`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from predictors import make_predictor, settings_for
from rhmpc.control.compiled_reference import compile_reference
from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.reference import ExactReference, PredictedReference
from rhmpc.errors import UsageError
from rhmpc.experiment.config import RunConfig
from robots import LinearArm, Robot, linearize, load_robot
from sim.loop.clock import PredictorClock, predictor_clock
from sim.loop.metrics import HeartRateScore
from sim.loop.streams import SampleSource, SourceTruth, UpsampledSamples, sensor_samples
from sim.sensors import DEFAULT_PLAYBACK, SampleStream, Sensor, playback, sensor_from_name
from sim.sources import HeartSource, heart_source

if TYPE_CHECKING:
    from rhmpc.control.export.binding import CController


@dataclass
class Run:
    """Everything a closed-loop run is made of, built from a :class:`RunConfig`.

    Attributes
    ----------
    config : RunConfig
    robot : Robot
        The plant's robot model.
    arm : LinearArm
        The controller's linear model about the home posture.
    controller : RecedingHorizonMPC or CController
        The Python MPC, or its compiled twin (``implementation="c"``).
    reference : ExactReference or PredictedReference
        What the MPC tracks: the true future, or a predictor's forecast.
    truth : SourceTruth
        The centred POI truth, read per window.
    center : ndarray, shape (d,)
        The POI's mean over the run [m].
    stream : SampleSource
        The sensor samples the controller sees, read in blocks.
    label : str
        The motion's name for reports.
    duration : float
        Simulated time [s].
    clock : PredictorClock
        When the predictor runs: every ``downsample`` ticks, or on each raw sample.
    refresh : str
        Who runs the predictor's refresh: ``"compiled"`` (C), ``"python (why)"``, or
        ``"none"`` for the exact reference.
    """

    config: RunConfig
    robot: Robot
    arm: LinearArm
    controller: RecedingHorizonMPC | CController
    reference: ExactReference | PredictedReference
    truth: SourceTruth
    center: np.ndarray
    stream: SampleSource
    label: str
    duration: float
    clock: PredictorClock
    refresh: str = "none"


def build_stream(config: RunConfig, heart: HeartSource, duration: float,
                 rng: np.random.Generator) -> SampleSource:
    """The sensor samples the controller sees (SI units), over ``duration`` seconds.

    A sample source read in blocks (:func:`sim.loop.streams.sensor_samples`): the samples and
    random draws of ``sensor.measure`` over the whole run, without holding the 2-kHz stream.
    """
    control_rate = 1.0 / config.loop.Ts
    settings = dict(config.sensor_settings)
    if config.sensor == "recorded":
        return _recorded_stream(config, heart.origin, settings, control_rate)
    if config.sensor in ("sonomicrometry", "white"):
        settings.setdefault("rate", getattr(heart.origin, "sensor_rate", None) or 257.0)
        settings.setdefault("upsample", control_rate)  # delivered to the 2-kHz loop
    sensor = make_sensor(config.sensor, heart.motion.dim, settings)
    return sensor_samples(sensor, heart.motion, duration, rng)


def _recorded_stream(config: RunConfig, recording, settings: dict,
                     control_rate: float) -> SampleSource:
    """A recording's own samples, delivered to the loop by its playback."""
    if config.data is None:
        raise UsageError("sensor 'recorded' needs a recording (--data FILE)")
    unknown = sorted(set(settings) - {"playback"})
    if unknown:
        raise UsageError(f"sensor 'recorded' has no setting(s) {', '.join(unknown)} "
                         "(only playback)")
    t = recording.t - recording.t[0]
    stream = SampleStream(t, recording.z, t.copy(), recording.sample_rate)
    try:
        delivery = playback(settings.get("playback", DEFAULT_PLAYBACK), control_rate)
    except ValueError as exc:
        raise UsageError(f"sensor 'recorded': {exc}") from None
    return UpsampledSamples(stream, delivery)


def make_sensor(name: str, dim: int, settings: dict) -> Sensor:
    """``sim.sensors.sensor_from_name(name, dim=dim, **settings)``; a bad setting raises
    ``UsageError`` naming the sensor (one line)."""
    try:
        return sensor_from_name(name, dim=dim, **settings)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"sensor {name!r}: {exc}") from None


def check_sensor(config: RunConfig) -> None:
    """Build the run's sensor once (no sampling) so that bad settings fail before any run."""
    if config.sensor != "recorded":
        make_sensor(config.sensor, 3, dict(config.sensor_settings))


def build_controller(config: RunConfig, arm: LinearArm,
                     implementation: str = "python") -> RecedingHorizonMPC | CController:
    """The MPC of ``config.mpc`` on ``arm``: Python, or its compiled twin (``"c"``)."""
    if config.mpc.horizon != config.loop.horizon:
        raise UsageError(f"mpc.horizon ({config.mpc.horizon}) and loop.horizon "
                         f"({config.loop.horizon}) must agree")
    if implementation not in ("python", "c"):
        raise UsageError(f"implementation must be 'python' or 'c', got {implementation!r}")
    controller = RecedingHorizonMPC(arm, config.mpc)
    if implementation == "c":
        from rhmpc.control.export import compiled_controller  # cmake and a compiler at first use

        controller = compiled_controller(controller, config.robot)
    return controller


def build_reference(config: RunConfig, truth: SourceTruth, heart: HeartSource,
                    clock: PredictorClock) -> tuple[ExactReference | PredictedReference, str]:
    """The exact future (``predictor = "exact"``) or the predictor's forecast on ``clock``,
    and who runs its refresh (:attr:`Run.refresh`): the compiled twin of the Python pipeline
    where ``loop.compiled_refresh`` allows it and it exists
    (:func:`rhmpc.control.compiled_reference.compile_reference`)."""
    loop = config.loop
    if config.predictor == "exact":
        return ExactReference(truth, loop.horizon), "none"
    settings = dict(config.predictor_settings)
    if config.predictor in config.predictor_params and "params" not in settings:
        settings["params"] = config.predictor_params[config.predictor]
    if "unit" not in settings and getattr(settings_for(config.predictor, **settings), "unit",
                                          1.0) is None:
        # the loop feeds metres: no unit inference, which would hold the first 0.5 s and then
        # replay it in one refresh (≈ 1 ms on one tick)
        settings["unit"] = 1.0
    predictor = make_predictor(config.predictor, dt=clock.dt, **settings)
    reference = PredictedReference(
        predictor, loop.Ts, loop.horizon, clock.refresh_ticks, loop.prediction_points,
        outlier_gate=loop.gate_floor, max_rejections=loop.outlier_max_rejections,
        gate_calibration=math.ceil(loop.gate_calibration / clock.dt),
        guard_speed=loop.guard_speed, guard_margin=loop.guard_margin,
    )
    phase = getattr(heart.motion, "phase", None)
    if hasattr(predictor, "heart_rate_hz") and hasattr(phase, "rate"):
        reference.monitor = HeartRateScore(phase.rate, loop.settling)  # ω̂ against the true rate
    if not loop.compiled_refresh:
        return reference, "python (loop.compiled_refresh = false)"
    compiled, why = compile_reference(reference, dim=truth.center.shape[0])
    return (compiled, "compiled") if compiled is not None else (reference, f"python ({why})")


def build_run(config: RunConfig, implementation: str = "python") -> Run:
    """Build robot, controller, heart motion, sensor stream and reference for ``config``.

    ``implementation="c"``: the controller is the compiled one of ``rhmpc export`` (built once
    and cached, :func:`rhmpc.control.export.compiled_controller`) instead of the Python one.
    """
    loop = config.loop
    heart_rng, sensor_rng = np.random.default_rng(config.seed).spawn(2)
    robot = load_robot(config.robot)
    arm = linearize(robot, Ts=loop.Ts)
    controller = build_controller(config, arm, implementation)
    heart = heart_source(config.scenario, heart_rng, data=config.data,
                         data_read=config.data_read, rr=config.rr,
                         needed=loop.duration + loop.horizon * loop.Ts + 1.0)
    if config.data is not None and loop.duration > heart.duration:
        available = heart.duration
        digits = next((d for d in range(2, 10)
                       if f"{available:.{d}f}" != f"{loop.duration:.{d}f}"), 9)
        raise UsageError(
            f"{config.data}: the recording lasts {available:.{digits}f} s, the run asks for "
            f"{loop.duration:.{digits}f} s (set --duration)"
        )
    stream = build_stream(config, heart, loop.duration + (loop.horizon + 1) * loop.Ts, sensor_rng)
    # the truth, read per window: "recorded" — the sensor's samples as recorded (before their
    # delivery to the loop), linearly interpolated at the ticks, as the paper's prerecorded
    # data — or the true motion
    recorded = getattr(stream, "recorded", stream)
    truth = SourceTruth(recorded if config.ground_truth == "recorded" else heart.motion,
                        loop.ticks + loop.horizon + 1, loop.Ts)
    clock = predictor_clock(loop, stream)
    reference, refresh = build_reference(config, truth, heart, clock)
    return Run(config, robot, arm, controller, reference, truth, truth.center, stream,
               heart.label, loop.duration, clock, refresh)
