"""The assembly of a run's world: robot, controller, heart motion, sensor stream, reference.

This is where the packages meet: ``robots`` (model, linearisation), ``sim`` (heart motion,
sensor, plant, loop), ``predictors`` and the controller of :mod:`rhmpc.control`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from predictors import make_predictor, settings_for
from rhmpc.control.cancellation import NonlinearityCancellation
from rhmpc.control.controller import Controller
from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.observer import JointObserver
from rhmpc.control.reference import ExactReference, PredictedReference
from rhmpc.errors import UsageError
from rhmpc.experiment.config import RunConfig
from rhmpc.experiment.fitting import fit_predictor
from rhmpc.experiment.monitor import HeartRateScore
from robots import LinearArm, Robot, linearize, load_robot
from sim.loop.clock import PredictorClock, clock_for_rate, predictor_clock
from sim.loop.faults import FaultyEncoders, split_faults
from sim.loop.streams import SourceTruth
from sim.plant import make_plant
from sim.recordings.points import PointsAt
from sim.sensors import DEFAULT_PLAYBACK, SampleStream, Sensor, playback, sensor_from_name
from sim.sensors.faults import FaultySamples
from sim.sensors.playback import UpsampledSamples, sensor_samples
from sim.sensors.stream import SampleSource
from sim.sources import HeartSource, heart_source

if TYPE_CHECKING:
    from rhmpc.control.export.binding import CController

#: Who runs the controller: this package's Python, or the C of ``rhmpc export``.
IMPLEMENTATIONS: tuple[str, ...] = ("python", "c")


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
    plant
        The plant (:func:`sim.plant.make_plant`).
    controller : Controller or CController
        The Python controller, or the exported C one (``implementation="c"``).
    truth : SourceTruth
        The centred POI truth, read per window.
    anchor : ndarray, shape (3,)
        Where the centred motion's origin sits in the workspace [m].
    stream : SampleSource
        The sensor samples the controller sees, read in blocks.
    label : str
        The motion's name for reports.
    duration : float
        Simulated time [s].
    clock : PredictorClock
        When the reference refreshes: every ``downsample`` ticks, or on each raw sample.
    faults : tuple
        The injected faults (:mod:`sim.sensors.faults`), already in ``stream`` and ``plant``.
    points : PointsAt or None
        The other tracked points of a recording, which the loop gives with each sample.
    measured : tuple or None
        A recording's own samples (t [s] from 0, z (n, d) [m]): where the run is scored.
    """

    config: RunConfig
    robot: Robot
    arm: LinearArm
    plant: object
    controller: Controller | CController
    truth: SourceTruth
    anchor: np.ndarray
    stream: SampleSource
    label: str
    duration: float
    clock: PredictorClock
    faults: tuple = ()
    points: PointsAt | None = None
    measured: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def reference(self):
        """The controller's reference (the Python controller's; None for the C one)."""
        return getattr(self.controller, "reference", None)


def build_stream(config: RunConfig, heart: HeartSource, duration: float,
                 rng: np.random.Generator) -> SampleSource:
    """The sensor samples the controller sees (SI units), over ``duration`` seconds.

    A sample source read in blocks (:func:`sim.sensors.playback.sensor_samples`): the samples and
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


def build_reference(config: RunConfig, truth: SourceTruth, heart: HeartSource,
                    clock: PredictorClock) -> ExactReference | PredictedReference:
    """The exact future (``predictor = "exact"``) or the predictor's forecast on ``clock``."""
    N = config.mpc.horizon
    if config.predictor == "exact":
        return ExactReference(truth, N)
    settings = dict(config.predictor_settings)
    if config.predictor in config.predictor_params and "params" not in settings:
        settings["params"] = config.predictor_params[config.predictor]
    if "unit" not in settings and getattr(settings_for(config.predictor, **settings), "unit",
                                          1.0) is None:
        settings["unit"] = 1.0  # the loop feeds metres: no unit inference
    predictor = make_predictor(config.predictor, dt=clock.dt, **settings)
    reference = PredictedReference(predictor, config.loop.Ts, N, clock.refresh_ticks,
                                   config.reference)
    phase = getattr(getattr(heart, "motion", None), "phase", None)
    if hasattr(predictor, "heart_rate_hz") and hasattr(phase, "rate"):
        reference.monitor = HeartRateScore(phase.rate, config.loop.settling_s)
    return reference


def build_controller(config: RunConfig, robot: Robot, arm: LinearArm, reference,
                     implementation: str = "python") -> Controller | CController:
    """The controller of ``config`` around ``reference`` (already placed): Python, or the C of
    ``rhmpc export`` (``"c"``, built once and cached)."""
    if implementation not in IMPLEMENTATIONS:
        raise UsageError(f"implementation must be one of {', '.join(IMPLEMENTATIONS)}, "
                         f"got {implementation!r}")
    linear = config.plant.model == "linear"
    cancellation = None if linear else NonlinearityCancellation(
        robot, config.mismatch, config.plant.stiction_velocity)
    delay = config.hardware.delay_ticks if config.plant.model == "hardware" else 0
    controller = Controller(RecedingHorizonMPC(arm, config.mpc), reference,
                            JointObserver(arm, robot.encoder_resolution, config.observer),
                            cancellation, robot.torque_limit, delay)
    if implementation == "c":
        from rhmpc.control.export import controller_in_c  # a C compiler at first use

        return controller_in_c(controller, config.robot)
    return controller


def deployable(config: RunConfig, sensor_rate: float) -> Controller:
    """The Python controller of ``config`` for a sensor of ``sensor_rate`` [Hz] (what ``rhmpc
    export`` generates from): the reference refreshes on each sample of a sensor slower than
    every ``loop.downsample`` ticks, else every ``downsample`` ticks; placed at the tool's home
    position plus ``loop.poi_offset``."""
    if not (np.isfinite(sensor_rate) and sensor_rate > 0):
        raise UsageError(f"the sensor's rate must be > 0 Hz, got {sensor_rate!r}")
    robot = load_robot(config.robot)
    arm = linearize(robot, Ts=config.loop.Ts)
    clock = clock_for_rate(config.loop, sensor_rate)
    if config.predictor == "exact":
        raise UsageError("the controller to deploy needs a predictor ('exact' reads the future)")
    reference = build_reference(config, None, None, clock)
    reference.place(motion_anchor(config, arm))
    return build_controller(config, robot, arm, reference)


#: Points of the POI's path checked against the arm's reach before a run.
REACH_POINTS = 200
#: Distances below this are reachable (the search's own tolerance) [m].
REACH_TOLERANCE = 1e-4


def check_reach(robot: Robot, truth, anchor: np.ndarray, ticks: int) -> float:
    """The farthest the POI's path (``anchor`` + the centred truth over ``ticks``) lies from
    the end-effector positions the joint limits allow [m].

    Measured by :meth:`robots.Robot.distance_to_reach` at :data:`REACH_POINTS` points; a path
    outside is warned about, with the distance and the fix. The run goes on: the controller
    keeps the arm in its envelope and takes its safe actions (a recorded jump can leave the
    workspace for a moment)."""
    from rhmpc.control.reference import embed3

    worst, at, q = 0.0, 0.0, robot.q0
    for tick in np.linspace(0, ticks - 1, min(REACH_POINTS, ticks)).astype(int):
        point = anchor + embed3(truth.window(int(tick), int(tick) + 1))[0]
        if not np.all(np.isfinite(point)):
            continue
        distance, q = robot.distance_to_reach(point, q)
        if distance > worst:
            worst, at = distance, tick * truth.Ts if hasattr(truth, "Ts") else float(tick)
    if worst <= REACH_TOLERANCE:
        return worst
    where = (f"the POI's path leaves the arm's workspace by up to {1e3 * worst:.1f} mm (at "
             f"{at:.2f} s) within its joint limits")
    warnings.warn(f"{where}: unreachable, the tool cannot follow there (bring it within reach "
                  "with loop.poi_offset or loop.placement)", UserWarning, stacklevel=2)
    return worst


def motion_anchor(config: RunConfig, arm: LinearArm) -> np.ndarray:
    """Where the centred motion's origin sits in the workspace [m] (``loop.placement``)."""
    offset = np.asarray(config.loop.poi_offset, dtype=float)
    return arm.y0 + offset if config.loop.placement == "centred" else offset


def build_run(config: RunConfig, implementation: str = "python", progress=None) -> Run:
    """Build robot, plant, controller, heart motion and sensor stream for ``config``.

    ``implementation="c"``: the controller is the C one of ``rhmpc export`` (built once and
    cached, :func:`rhmpc.control.export.controller_in_c`) instead of the Python one. A
    predictor that learns before the run is fitted (:mod:`rhmpc.experiment.fitting`);
    ``progress(text)`` hears how that goes.
    """
    loop, N = config.loop, config.mpc.horizon
    heart_rng, sensor_rng = np.random.default_rng(config.seed).spawn(2)
    robot = load_robot(config.robot)
    arm = linearize(robot, Ts=loop.Ts)
    heart = heart_source(config.scenario, heart_rng, data=config.data,
                         data_read=config.data_read, rr=config.rr,
                         needed=loop.duration + N * loop.Ts + 1.0)
    if config.data is not None and loop.duration > heart.duration:
        available = heart.duration
        digits = next((d for d in range(2, 10)
                       if f"{available:.{d}f}" != f"{loop.duration:.{d}f}"), 9)
        raise UsageError(
            f"{config.data}: the recording lasts {available:.{digits}f} s, the run asks for "
            f"{loop.duration:.{digits}f} s (set --duration)"
        )
    stream = build_stream(config, heart, loop.duration + (N + 1) * loop.Ts, sensor_rng)
    # the truth, read per window: "recorded" — the sensor's samples as recorded (before their
    # delivery to the loop), linearly interpolated at the ticks, as the paper's prerecorded
    # data — or the true motion
    recorded = getattr(stream, "recorded", stream)
    truth = SourceTruth(recorded if config.ground_truth == "recorded" else heart.motion,
                        loop.ticks + N + 1, loop.Ts,
                        centred=loop.placement == "centred")
    sensor_faults, encoder_faults = split_faults(config.faults.faults)
    if sensor_faults:  # what the controller reads; the truth above is the clean stream's
        stream = FaultySamples(stream, sensor_faults)
    clock = predictor_clock(loop, stream)
    anchor = motion_anchor(config, arm)
    check_reach(robot, truth, anchor, loop.ticks)
    reference = build_reference(config, truth, heart, clock)
    reference.place(anchor)
    controller = build_controller(config, robot, arm, reference, implementation)
    plant = make_plant(robot, arm, loop.Ts, config.plant, config.hardware)
    if encoder_faults:
        try:
            plant = FaultyEncoders(plant, encoder_faults, loop.Ts)
        except ValueError as exc:
            raise UsageError(f"[faults] {exc}") from None
    points = None if heart.others is None else PointsAt(heart.origin.t - heart.origin.t[0],
                                                        heart.others)
    measured = None if config.data is None else (heart.origin.t - heart.origin.t[0],
                                                  heart.origin.z)
    run = Run(config, robot, arm, plant, controller, truth, anchor, stream, heart.label,
              loop.duration, clock, config.faults.faults, points, measured)
    fit_predictor(run, progress)
    return run
