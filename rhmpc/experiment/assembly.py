"""The assembly of a run's world from its settings, one function per thing it builds.

:func:`build_run` takes a :class:`~rhmpc.experiment.config.RunConfig` and builds, in order,
the robot and its linear model (:func:`build_robot`), the heart motion (:func:`build_heart`),
the sensor's samples and the truth (:func:`build_stream`), the predictor and the reference
(:func:`build_reference`), the controller (:func:`build_controller`) and the plant
(:func:`build_plant`); each hands its part of the settings down to the package that holds the
thing (``rhmpc.robots``, ``rhmpc.sim``, ``rhmpc.predictors``, :mod:`rhmpc.control`) and none calls
back up.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from rhmpc.control.cancellation import NonlinearityCancellation
from rhmpc.control.controller import Controller
from rhmpc.control.export import PREDICTORS, ToolchainError
from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.observer import JointObserver
from rhmpc.control.reference import PredictedReference
from rhmpc.errors import UsageError
from rhmpc.experiment.config import RunConfig
from rhmpc.experiment.fitting import fit_predictor
from rhmpc.experiment.monitor import HeartRateScore
from rhmpc.predictors.registry import make_predictor
from rhmpc.robots import LinearArm, Robot, linearize, load_robot
from rhmpc.sim.loop.clock import PredictorClock, clock_for_rate, predictor_clock
from rhmpc.sim.loop.exact import ExactReference
from rhmpc.sim.loop.faults import FaultyEncoders, split_faults
from rhmpc.sim.loop.streams import SourceTruth
from rhmpc.sim.plant import make_plant
from rhmpc.sim.recordings.points import PointsAt
from rhmpc.sim.sensors import DEFAULT_PLAYBACK, SampleStream, Sensor, playback, sensor_from_name
from rhmpc.sim.sensors.faults import FaultySamples
from rhmpc.sim.sensors.playback import UpsampledSamples, sensor_samples
from rhmpc.sim.sensors.stream import SampleSource
from rhmpc.sim.sources import HeartSource, heart_source

#: Who serves the reference's refreshes: the run's predictor (Python, ``rhmpc.predictors``), or
#: the controller library's own RLS predictor (``"c"``: a target with no predictor process).
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
        The plant (:func:`build_plant`).
    controller : Controller
        The controller (its library: :class:`rhmpc.control.controller.Controller`).
    truth : SourceTruth
        The centred POI truth, read per window.
    anchor : ndarray, shape (3,)
        Where the motion's mean sits in the workspace [m] (its reference placed with the
        mean as the sensor's point there).
    stream : SampleSource
        The sensor samples the controller sees, read in blocks.
    label : str
        The motion's name for reports.
    duration : float
        Simulated time [s].
    clock : PredictorClock
        When the reference refreshes: every ``downsample`` ticks, or on each raw sample.
    faults : tuple
        The injected faults (:mod:`rhmpc.sim.sensors.faults`), already in ``stream`` and ``plant``.
    points : PointsAt or None
        The other tracked points of a recording, which the loop gives with each sample.
    measured : tuple or None
        A recording's own samples (t [s] from 0, z (n, d) [m]): where the run is scored.
    reference : ExactReference or PredictedReference or None
        The controller's reference.
    """

    config: RunConfig
    robot: Robot
    arm: LinearArm
    plant: object
    controller: Controller
    truth: SourceTruth
    anchor: np.ndarray
    stream: SampleSource
    label: str
    duration: float
    clock: PredictorClock
    faults: tuple = ()
    points: PointsAt | None = None
    measured: tuple[np.ndarray, np.ndarray] | None = None
    reference: ExactReference | PredictedReference | None = None


def build_run(config: RunConfig, implementation: str = "python", progress=None) -> Run:
    """Build robot, heart motion, sensor stream, reference, controller and plant for ``config``.

    ``implementation="c"``: the controller library's own RLS predictor serves the refreshes
    instead of the run's Python predictor (``one-step`` and ``generalized`` only). A
    predictor that learns before the run is fitted (:mod:`rhmpc.experiment.fitting`);
    ``progress(text)`` hears how that goes.
    """
    heart_rng, sensor_rng = np.random.default_rng(config.seed).spawn(2)
    robot, arm = build_robot(config)
    heart = build_heart(config, heart_rng)
    stream, truth = build_stream(config, heart, sensor_rng)
    loop = config.loop
    clock = predictor_clock(loop, stream)
    anchor = motion_anchor(config, arm)
    check_reach(robot, truth, anchor, loop.ticks)
    reference = build_reference(config, truth, heart, clock)
    reference.place(anchor, truth.center)
    controller = build_controller(config, robot, arm, reference, implementation)
    plant = build_plant(config, robot, arm)
    run = Run(config, robot, arm, plant, controller, truth, anchor, stream, heart.label,
              loop.duration, clock, config.faults.faults, heart.points, heart.measured,
              reference)
    fit_predictor(run, progress)
    return run


def build_robot(config: RunConfig) -> tuple[Robot, LinearArm]:
    """The robot ``config.robot`` and its linear model about its home posture at the loop's
    period (:func:`rhmpc.robots.linearize`)."""
    robot = load_robot(config.robot)
    return robot, linearize(robot, Ts=config.loop.Ts)


def build_heart(config: RunConfig, rng: np.random.Generator) -> HeartSource:
    """The run's heart motion, a named scenario or a recording
    (:func:`rhmpc.sim.sources.heart_source`, a scenario's random processes drawn from ``rng`` over
    the run and its last horizon). A recording shorter than the run is a one-line ``UsageError``."""
    loop = config.loop
    heart = heart_source(config.scenario, rng, data=config.data, data_read=config.data_read,
                         rr=config.rr, needed=loop.duration + config.mpc.horizon * loop.Ts + 1.0)
    if config.data is not None and loop.duration > heart.duration:
        available = heart.duration
        digits = next((d for d in range(2, 10)
                       if f"{available:.{d}f}" != f"{loop.duration:.{d}f}"), 9)
        raise UsageError(
            f"{config.data}: the recording lasts {available:.{digits}f} s, the run asks for "
            f"{loop.duration:.{digits}f} s (set --duration)"
        )
    return heart


def build_stream(config: RunConfig, heart: HeartSource,
                 rng: np.random.Generator) -> tuple[SampleSource, SourceTruth]:
    """The sensor samples the controller sees (SI units) over the run and its last horizon,
    with the injected sensor faults, and the truth they are scored against.

    The samples are a source read in blocks (:func:`rhmpc.sim.sensors.playback.sensor_samples`: the
    samples and random draws of ``sensor.measure`` over the whole run, without holding the
    2-kHz stream), or a recording's own samples (``sensor = "recorded"``). The truth, read per
    window (:class:`rhmpc.sim.loop.streams.SourceTruth`), is the clean samples as recorded (before
    their delivery to the loop), linearly interpolated at the ticks, as the paper's
    prerecorded data (``ground_truth = "recorded"``), or the true motion (``"true"``).
    """
    loop, N = config.loop, config.mpc.horizon
    duration = loop.duration + (N + 1) * loop.Ts
    control_rate = 1.0 / loop.Ts
    settings = dict(config.sensor_settings)
    if config.sensor == "recorded":
        stream = _recorded_stream(config, heart.origin, settings, control_rate)
    else:
        if config.sensor in ("sonomicrometry", "white"):
            settings.setdefault("rate", getattr(heart.origin, "sensor_rate", None) or 257.0)
            settings.setdefault("upsample", control_rate)  # delivered to the 2-kHz loop
        sensor = make_sensor(config.sensor, heart.motion.dim, settings)
        stream = sensor_samples(sensor, heart.motion, duration, rng)
    recorded = getattr(stream, "recorded", stream)
    truth = SourceTruth(recorded if config.ground_truth == "recorded" else heart.motion,
                        loop.ticks + N + 1, loop.Ts, centred=loop.placement == "centred")
    sensor_faults, _ = split_faults(config.faults.faults)
    if sensor_faults:  # what the controller reads; the truth above is the clean stream's
        stream = FaultySamples(stream, sensor_faults)
    return stream, truth


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
    """``rhmpc.sim.sensors.sensor_from_name(name, dim=dim, **settings)``; a bad setting raises
    ``UsageError`` naming the sensor (one line)."""
    try:
        return sensor_from_name(name, dim=dim, **settings)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"sensor {name!r}: {exc}") from None


def build_reference(config: RunConfig, truth: SourceTruth, heart: HeartSource,
                    clock: PredictorClock) -> ExactReference | PredictedReference:
    """The exact future (``predictor = "exact"``) or the predictor's forecast on ``clock``.

    The predictor is built by name (:func:`rhmpc.predictors.registry.make_predictor`, which resolves
    the name once into its class and settings) with :meth:`RunConfig.predictor_keywords`, fed
    metres."""
    N = config.mpc.horizon
    if config.predictor == "exact":
        return ExactReference(truth, N)
    predictor = make_predictor(config.predictor, clock.dt, data_unit=1.0,
                               **config.predictor_keywords())
    reference = PredictedReference(predictor, config.loop.Ts, N, clock.refresh_ticks,
                                   config.reference)
    phase = getattr(getattr(heart, "motion", None), "phase", None)
    if hasattr(predictor, "heart_rate_hz") and hasattr(phase, "rate"):
        reference.monitor = HeartRateScore(phase.rate, config.loop.settling_s)
    return reference


def build_controller(config: RunConfig, robot: Robot, arm: LinearArm, reference,
                     implementation: str = "python") -> Controller:
    """The controller of ``config`` around ``reference``: its library, built once per distinct
    description and cached; ``"c"``: the library's own RLS predictor serves the refreshes."""
    if implementation not in IMPLEMENTATIONS:
        raise UsageError(f"implementation must be one of {', '.join(IMPLEMENTATIONS)}, "
                         f"got {implementation!r}")
    linear = config.plant.kind == "linear"
    cancellation = None if linear else NonlinearityCancellation(robot, config.mismatch)
    delay = 0 if linear else config.plant.delay_ticks
    if implementation == "c" and config.predictor not in PREDICTORS:
        raise UsageError(f"--controller c runs the library's own RLS predictor ("
                         f"{', '.join(PREDICTORS)}), not {config.predictor}")
    try:
        return Controller(RecedingHorizonMPC(arm, config.mpc), reference,
                          JointObserver(arm, robot.encoder_resolution, config.observer),
                          cancellation, robot.torque_limit, delay,
                          internal=implementation == "c")
    except ToolchainError as exc:
        raise UsageError(f"the controller's build: {exc}") from None


def build_plant(config: RunConfig, robot: Robot, arm: LinearArm):
    """The plant of ``config.plant`` (:func:`rhmpc.sim.plant.make_plant`) at the home posture, its
    encoders with the injected encoder faults."""
    loop = config.loop
    plant = make_plant(robot, arm, loop.Ts, config.plant)
    _, encoder_faults = split_faults(config.faults.faults)
    if not encoder_faults:
        return plant
    try:
        return FaultyEncoders(plant, encoder_faults, loop.Ts)
    except ValueError as exc:
        raise UsageError(f"[faults] {exc}") from None


def deployable(config: RunConfig, sensor_rate: float) -> Controller:
    """The Python controller of ``config`` for a sensor of ``sensor_rate`` [Hz] (what ``rhmpc
    export`` generates from): the reference refreshes on each sample of a sensor slower than
    every ``loop.downsample`` ticks, else every ``downsample`` ticks; placed at the tool's home
    position plus ``loop.poi_offset``."""
    if not (np.isfinite(sensor_rate) and sensor_rate > 0):
        raise UsageError(f"the sensor's rate must be > 0 Hz, got {sensor_rate!r}")
    robot, arm = build_robot(config)
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

    Measured by :meth:`rhmpc.robots.Robot.distance_to_reach` at :data:`REACH_POINTS` points; a path
    outside is warned about, with the distance and the fix. The run goes on: the controller
    keeps the arm in its envelope and takes its safe actions (a recorded jump can leave the
    workspace for a moment)."""
    from rhmpc.positions import embed3

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
    """Where the motion's mean sits in the workspace [m] (``loop.placement``)."""
    offset = np.asarray(config.loop.poi_offset, dtype=float)
    return arm.y0 + offset if config.loop.placement == "centred" else offset
