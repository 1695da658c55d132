"""One closed-loop run, from a :class:`RunConfig` to a JSON-ready result document.

This is where the packages meet: ``robots`` (model, linearisation), ``sim`` (heart motion,
sensor, plant, loop), ``predictors`` and the controller of :mod:`rhmpc.control`.
``rhmpc simulate``, ``rhmpc compare`` and ``rhmpc tune`` all run through :func:`run_experiment`.
"""

from __future__ import annotations

import dataclasses
import platform
import time
import tomllib
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import numpy as np

from rhmpc.control.settings import MPCSettings, from_dict, to_dict
from rhmpc.errors import UsageError
from sim.estimation import ObserverSettings
from sim.loop import LoopSettings
from sim.plant import ModelMismatch, PlantSettings

#: Sections of a run's TOML file and the settings class each one builds.
SECTIONS: dict[str, type] = {
    "loop": LoopSettings,
    "mpc": MPCSettings,
    "plant": PlantSettings,
    "mismatch": ModelMismatch,
    "observer": ObserverSettings,
}


GROUND_TRUTHS: tuple[str, ...] = ("recorded", "true")


@dataclass(frozen=True)
class RunConfig:
    """Every setting of a closed-loop run (what ``rhmpc simulate --config FILE.toml`` reads).

    Attributes
    ----------
    robot : str
        Registered robot name (``rhmpc robots``).
    scenario : str
        Named heart-motion scenario (``rhmpc data list``); ignored when ``data`` is given.
    data : str | None
        A recording (CSV/NPZ/MAT, see ``sim.recordings``) to track instead of a scenario.
    data_read : dict
        How to read it: ``load_recording`` keywords ``var``, ``rows``, ``cols``, ``rate`` [Hz],
        ``units`` (MATLAB files).
    rr : str | None
        PhysioNet record (path without extension) whose beat annotations drive the heart phase.
    sensor : str
        Sensor model name (``sim.sensors.SENSORS``: the physical ``sonomicrometry`` by
        default, ``white``, ``ultrasound``, ``ideal``), or ``"recorded"`` to use a recording's
        samples as they are.
    sensor_settings : dict
        Keyword settings of the sensor model (SI units, ``sim.sensors.sensor_from_name``),
        among them ``playback``: how the samples reach the 2-kHz loop, ``"linear"`` (causal
        interpolation one raw period late, default), ``"hold"`` (causal zero-order hold) or
        ``"offline"`` (the non-causal interpolation of a
        prerecorded file, Tuna et al.'s protocol).
    predictor : str
        Predictor name (``predictors.PREDICTORS``), or ``"exact"`` for the true future.
    predictor_settings : dict
        Keyword settings passed to ``predictors.make_predictor``.
    ground_truth : str
        What the error is measured against and what ``exact`` reads: ``"recorded"`` — the
        sensor's samples as recorded, linearly interpolated at the ticks (Tuna et al.'s
        protocol: the prerecorded data are the target, sensor errors and echo outliers
        included) — or ``"true"`` — the noise-free motion.
    seed : int
        Seed of the run's ``numpy.random.Generator`` (heart variability, sensor noise).
    loop, mpc, plant, mismatch, observer
        Component settings (see their classes for units).
    """

    robot: str = "phantom"
    scenario: str = "fixed-a2-top"
    data: str | None = None
    data_read: dict = field(default_factory=dict)
    rr: str | None = None
    sensor: str = "sonomicrometry"
    sensor_settings: dict = field(default_factory=dict)
    predictor: str = "generalized"
    predictor_settings: dict = field(default_factory=dict)
    ground_truth: str = "recorded"
    seed: int = 0
    loop: LoopSettings = field(default_factory=LoopSettings)
    mpc: MPCSettings = field(default_factory=MPCSettings)
    plant: PlantSettings = field(default_factory=PlantSettings)
    mismatch: ModelMismatch = field(default_factory=ModelMismatch)
    observer: ObserverSettings = field(default_factory=ObserverSettings)

    def __post_init__(self) -> None:
        if self.ground_truth not in GROUND_TRUTHS:
            raise ValueError(
                f"ground_truth must be one of {', '.join(GROUND_TRUTHS)}, got {self.ground_truth!r}"
            )

    def to_dict(self) -> dict[str, Any]:
        """TOML-ready nested dict (``None`` values left out)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name in SECTIONS:
                out[f.name] = to_dict(value)
            elif value is not None:
                out[f.name] = dict(value) if isinstance(value, dict) else value
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "config") -> RunConfig:
        """Build from a nested dict; unknown keys raise ``UsageError`` naming the key."""
        names = {f.name for f in dataclasses.fields(cls)}
        kwargs: dict[str, Any] = {}
        for key, value in data.items():
            if key not in names:
                raise UsageError(
                    f"{where}: unknown key {key!r}; valid keys: {', '.join(sorted(names))}"
                )
            if key in SECTIONS:
                if not isinstance(value, dict):
                    raise UsageError(f"{where}: [{key}] must be a table")
                try:
                    kwargs[key] = from_dict(SECTIONS[key], value)
                except (TypeError, ValueError) as exc:
                    raise UsageError(f"{where}: [{key}] {exc}") from None
            elif key in ("sensor_settings", "predictor_settings"):
                if not isinstance(value, dict):
                    raise UsageError(f"{where}: [{key}] must be a table")
                kwargs[key] = dict(value)
            else:
                kwargs[key] = value
        try:
            return cls(**kwargs)
        except (TypeError, ValueError) as exc:
            raise UsageError(f"{where}: {exc}") from None

    def replace(self, **changes: Any) -> RunConfig:
        """A copy with top-level or dotted section fields (``"mpc.effort_weight"``) changed."""
        top: dict[str, Any] = {}
        nested: dict[str, dict[str, Any]] = {}
        for key, value in changes.items():
            section, _, name = key.partition(".")
            if name:
                nested.setdefault(section, {})[name] = value
            else:
                top[key] = value
        for section, values in nested.items():
            if section in SECTIONS:
                try:
                    top[section] = dataclasses.replace(getattr(self, section), **values)
                except (TypeError, ValueError) as exc:
                    raise UsageError(f"[{section}] {exc}") from None
            elif section in ("sensor_settings", "predictor_settings"):
                top[section] = {**getattr(self, section), **values}
            else:
                raise UsageError(f"unknown setting {section}.{next(iter(values))!r}")
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(top) - names)
        if unknown:
            raise UsageError(f"unknown setting(s) {', '.join(unknown)}; valid: "
                             f"{', '.join(sorted(names))}")
        try:
            return dataclasses.replace(self, **top)
        except (TypeError, ValueError) as exc:
            raise UsageError(str(exc)) from None


def read_toml(path: str | Path) -> dict[str, Any]:
    """A TOML file as a ``dict``; unreadable or invalid files raise ``UsageError`` naming it."""
    path = Path(path)
    try:
        return tomllib.loads(path.read_text())
    except OSError as exc:
        raise UsageError(f"{path}: cannot read: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise UsageError(f"{path}: not valid TOML: {exc}") from None


def load_config(path: str | Path) -> RunConfig:
    """Read a run's TOML file; errors name the file and the key."""
    return RunConfig.from_dict(read_toml(path), where=str(path))


def save_config(config: RunConfig, path: str | Path) -> None:
    import tomli_w

    Path(path).write_text(tomli_w.dumps(config.to_dict()))


def versions() -> dict[str, str]:
    """Versions of the packages a result depends on."""
    out = {"python": platform.python_version()}
    for name in ("rhmpc", "pin", "osqp", "casadi", "numpy", "scipy"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "not installed"
    return out


class _Shifted:
    """A motion source read from ``t0`` on, so that the run starts at t = 0."""

    def __init__(self, source, t0: float) -> None:
        self.source, self.t0, self.dim = source, float(t0), source.dim

    def position(self, t):
        return self.source.position(np.asarray(t, dtype=float) + self.t0)


@dataclass
class Run:
    """Everything a closed-loop run is made of, built from a :class:`RunConfig`."""

    config: RunConfig
    robot: Any
    arm: Any
    controller: Any
    reference: Any
    truth: Any  # sim.streams.SourceTruth: the centred POI truth, read per window
    center: np.ndarray
    stream: Any  # a sample source of sim.streams
    label: str
    duration: float


def heart_source(config: RunConfig, rng: np.random.Generator):
    """The true motion and its label: a recording (``data``) or a named scenario (``rr``)."""
    from sim.heart import load_recording, make_scenario
    from sim.scenarios import SPECS

    if config.data is not None:
        recording = load_recording(config.data, **config.data_read)
        source = _Shifted(recording, recording.t[0]) if recording.t[0] != 0 else recording
        return source, f"file:{Path(config.data).name}", recording.duration, recording
    overrides = {"record": config.rr} if config.rr else {}
    # The scenario's random processes (HRV, drift, breathing) are drawn over its nominal length
    # or the run's, whichever is longer; past that they would be extrapolated polynomials.
    # Only a longer run asks for more, so the draws of shorter runs stay as they were.
    needed = config.loop.duration + config.loop.horizon * config.loop.Ts + 1.0
    spec = SPECS.get(config.scenario)  # an unknown name: make_scenario says so
    if spec is not None and needed > spec.duration:
        overrides["duration"] = needed
    scenario = make_scenario(config.scenario, rng=rng, **overrides)
    label = scenario.name + (f"+rr:{Path(config.rr).name}" if config.rr else "")
    return scenario.source, label, scenario.duration, scenario


def build_stream(config: RunConfig, source, origin, duration: float, rng: np.random.Generator):
    """The sensor samples the controller sees (SI units), over ``duration`` seconds.

    A sample source read in blocks (:func:`sim.streams.sensor_samples`): the samples and random
    draws of ``sensor.measure`` over the whole run, without holding the 2-kHz stream.
    """
    from sim.sensors import DEFAULT_PLAYBACK, SampleStream, playback
    from sim.streams import UpsampledSamples, sensor_samples

    control_rate = 1.0 / config.loop.Ts
    settings = dict(config.sensor_settings)
    if config.sensor == "recorded":
        if config.data is None:
            raise UsageError("sensor 'recorded' needs a recording (--data FILE)")
        unknown = sorted(set(settings) - {"playback"})
        if unknown:
            raise UsageError(f"sensor 'recorded' has no setting(s) {', '.join(unknown)} "
                             "(only playback)")
        t = origin.t - origin.t[0]
        stream = SampleStream(t, origin.z, t.copy(), origin.sample_rate)
        try:
            delivery = playback(settings.get("playback", DEFAULT_PLAYBACK), control_rate)
        except ValueError as exc:
            raise UsageError(f"sensor 'recorded': {exc}") from None
        return UpsampledSamples(stream, delivery)
    if config.sensor in ("sonomicrometry", "white"):
        settings.setdefault("rate", getattr(origin, "sensor_rate", None) or 257.0)
        settings.setdefault("upsample", control_rate)  # delivered to the 2-kHz loop
    sensor = make_sensor(config.sensor, source.dim, settings)
    return sensor_samples(sensor, source, duration, rng)


def make_sensor(name: str, dim: int, settings: dict):
    """``sim.sensors.sensor_from_name(name, dim=dim, **settings)``; a bad setting raises
    ``UsageError`` naming the sensor (one line)."""
    from sim.sensors import sensor_from_name

    try:
        return sensor_from_name(name, dim=dim, **settings)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"sensor {name!r}: {exc}") from None


def check_sensor(config: RunConfig) -> None:
    """Build the run's sensor once (no sampling) so that bad settings fail before any run."""
    if config.sensor != "recorded":
        make_sensor(config.sensor, 3, dict(config.sensor_settings))


def build_run(config: RunConfig, implementation: str = "python") -> Run:
    """Build robot, controller, heart motion, sensor stream and reference for ``config``.

    ``implementation="c"``: the controller is the compiled one of ``rhmpc export`` (built once
    and cached, :func:`rhmpc.control.export.compiled_controller`) instead of the Python one.
    """
    from predictors import make_predictor
    from rhmpc.control.mpc import RecedingHorizonMPC
    from rhmpc.control.reference import ExactReference, PredictedReference
    from robots import linearize, load_robot
    from sim.streams import SourceTruth

    loop = config.loop
    if config.mpc.horizon != loop.horizon:
        raise UsageError(
            f"mpc.horizon ({config.mpc.horizon}) and loop.horizon ({loop.horizon}) must agree"
        )
    rng = np.random.default_rng(config.seed)
    heart_rng, sensor_rng = rng.spawn(2)
    robot = load_robot(config.robot)
    arm = linearize(robot, Ts=loop.Ts)
    controller = RecedingHorizonMPC(arm, config.mpc)
    if implementation == "c":
        from rhmpc.control.export import compiled_controller

        controller = compiled_controller(controller, config.robot)
    elif implementation != "python":
        raise UsageError(f"implementation must be 'python' or 'c', got {implementation!r}")
    source, label, available, origin = heart_source(config, heart_rng)
    if config.data is not None and loop.duration > available:
        digits = next((d for d in range(2, 10) if f"{available:.{d}f}" != f"{loop.duration:.{d}f}"),
                      9)
        raise UsageError(
            f"{config.data}: the recording lasts {available:.{digits}f} s, the run asks for "
            f"{loop.duration:.{digits}f} s (set --duration)"
        )
    margin = (loop.horizon + 1) * loop.Ts
    stream = build_stream(config, source, origin, loop.duration + margin, sensor_rng)
    # the truth is read per window: the recorded stream interpolated at the ticks, or the motion
    # "recorded": the sensor's samples as recorded (before the delivery to the loop), linearly
    # interpolated at the ticks, as the paper's prerecorded data
    recorded = getattr(stream, "recorded", stream)
    truth = SourceTruth(recorded if config.ground_truth == "recorded" else source,
                        loop.ticks + loop.horizon + 1, loop.Ts)
    center = truth.center
    if config.predictor == "exact":
        reference = ExactReference(truth, loop.horizon)
    else:
        predictor = make_predictor(
            config.predictor, dt=loop.downsample * loop.Ts, **config.predictor_settings
        )
        reference = PredictedReference(
            predictor, loop.Ts, loop.horizon, loop.downsample, loop.prediction_points,
            outlier_gate=loop.outlier_gate, max_rejections=loop.outlier_max_rejections,
            guard_speed=loop.guard_speed, guard_margin=loop.guard_margin,
        )
        phase = getattr(source, "phase", None)
        if hasattr(predictor, "heart_rate_hz") and hasattr(phase, "rate"):
            from sim.metrics import HeartRateScore  # ω̂ against the true rate, as Yuen reports

            reference.monitor = HeartRateScore(phase.rate, loop.settling)
    return Run(config, robot, arm, controller, reference, truth, center, stream, label,
               loop.duration)


def run_experiment(config: RunConfig, progress: bool = False, trace: str | None = None,
                   gain_tick=None, implementation: str = "python") -> tuple[Any, dict]:
    """Run ``config`` in closed loop; returns the :class:`~sim.loop.LoopResult` and its document.

    The document holds the settings, the metrics (``rms_error_mm``, ``max_error_mm``,
    ``rms_effort_mNm``, ``tick_us`` with ``p50``/``p99``/``max``, ``fallbacks`` …), the wall
    time, the peak resident memory of the process so far (``peak_rss_mb``) and the package
    versions. ``trace``: write every tick to this NPZ file (:mod:`sim.trace`). ``gain_tick``:
    the class of ``rhmpc bench``'s gain tick (``GainTick(mpc)(x, r, u_prev)``), timed in the
    run on every 16th tick so that the document has ``gain_tick_us`` and the tick's ratios to
    its p50 (``tick_ratio_to_gain``).
    ``implementation``: ``"python"`` or ``"c"`` (:func:`build_run`).
    """
    import resource

    from sim.loop import run_closed_loop

    run = build_run(config, implementation)
    bar = None
    callback = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=config.loop.ticks, unit="tick", unit_scale=True, leave=False,
                   desc=f"{config.predictor} on {run.label}", mininterval=0.5)

        def callback(done: int) -> None:
            bar.update(done - bar.n)

    wall = time.perf_counter()
    try:
        result = run_closed_loop(
            run.robot, run.arm, run.controller, run.reference, run.truth, run.center, run.stream,
            config.loop, plant_settings=config.plant, mismatch=config.mismatch,
            observer_settings=config.observer, progress=callback, trace_file=trace,
            yardstick=None if gain_tick is None else _gain_tick(run.controller, gain_tick),
        )
    finally:
        if bar is not None:
            bar.close()
    wall = time.perf_counter() - wall
    metrics = result.metrics()
    stats = result.controller_stats
    document = {
        "predictor": config.predictor,
        "scenario": run.label,
        "robot": config.robot,
        "seed": config.seed,
        "sensor": config.sensor,
        "ground_truth": config.ground_truth,
        **metrics,
        "fallbacks": int(stats.get("fallback_total", 0)),
        "controller": _jsonable(stats),
        "implementation": implementation,
        "predictor_counts": _jsonable(result.predictor_counts),
        "wall_s": wall,
        "real_time_factor": config.loop.duration / wall,
        "plant_dynamics": result.plant_dynamics,
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,  # Linux: KiB
        "settings": config.to_dict(),
        "versions": versions(),
    }
    predictor = getattr(run.reference, "predictor", None)
    if predictor is not None:  # its running RMS miss per lead (rhmpc.control.confidence)
        errors = np.asarray(predictor.forecast_error_rms, dtype=float)
        document["forecast_error_rms_mm"] = [None if not np.isfinite(v) else 1e3 * float(v)
                                             for v in errors]
        document["forecast_lead_s"] = config.loop.downsample * config.loop.Ts
    monitor = getattr(run.reference, "monitor", None)
    if monitor is not None:
        document["heart_rate"] = monitor.summary()
    if gain_tick is not None:
        document["gain_tick_us"] = result.yardstick_us
        document["tick_ratio_to_gain"] = {k: v / result.yardstick_us["p50"]
                                          for k, v in metrics["tick_us"].items() if k != "mean"}
    return result, document


def _gain_tick(controller, gain_tick):
    """``yardstick(x, r)``: the controller's gain tick, or None if it has no gain to time."""
    try:
        gain = gain_tick(getattr(controller, "twin", controller))  # compiled: its Python twin
    except AttributeError:  # a stand-in controller without the MPC's QP
        return None
    return lambda x, ref: gain(x, ref, controller.u_prev)


def _jsonable(obj: Any) -> Any:
    """Plain JSON types for stats mappings (numpy scalars, tuples, nested dicts)."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    return obj
