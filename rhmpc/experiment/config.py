"""A run's configuration: every setting of a closed-loop run, and its TOML file."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rhmpc import io
from rhmpc.control.cancellation import ModelMismatch
from rhmpc.control.observer import ObserverSettings
from rhmpc.control.reference import ReferenceSettings
from rhmpc.control.settings import MPCSettings
from rhmpc.errors import UsageError
from rhmpc.experiment.presets import preset_settings
from rhmpc.experiment.tables import from_dict, replace_settings, to_dict
from rhmpc.io import FileError
from rhmpc.sim.loop import LoopSettings
from rhmpc.sim.plant import PlantSettings
from rhmpc.sim.sensors import sensor_from_name
from rhmpc.sim.sensors.faults import FaultSettings, parse_fault

#: Sections of a run's TOML file and the settings class each one builds.
SECTIONS: dict[str, type] = {
    "loop": LoopSettings,
    "reference": ReferenceSettings,
    "mpc": MPCSettings,
    "plant": PlantSettings,
    "mismatch": ModelMismatch,
    "observer": ObserverSettings,
    "faults": FaultSettings,
}


GROUND_TRUTHS: tuple[str, ...] = ("recorded", "true")
#: The shortest stretch after settling that a run is scored on [s]: ten 25-ms horizons.
MIN_SCORED = 0.25

#: The type of each top-level setting of a run (the sections check their own fields).
TOP_LEVEL: dict[str, object] = {
    "robot": str, "scenario": str, "data": (str, None), "data_read": dict, "rr": (str, None),
    "sensor": str, "sensor_settings": dict, "predictor": str, "predictor_settings": dict,
    "predictor_params": dict, "ground_truth": str, "seed": int, "train": tuple,
}
KIND_NAMES = {str: "a name (a string)", (str, None): "a string or absent", dict: "a table",
              int: "an integer", tuple: "a list of file names"}


def _is(value: Any, kind: object) -> bool:
    """Whether ``value`` is of ``kind`` (a type, or (type, None) for an optional one); a bool is
    not an integer."""
    if isinstance(kind, tuple):
        return value is None or isinstance(value, kind[0])
    return isinstance(value, kind) and not (kind is int and isinstance(value, bool))

#: Tables of a run's TOML file whose keys are free (passed on, checked by what takes them).
FREE_TABLES: tuple[str, ...] = ("sensor_settings", "predictor_settings", "predictor_params")


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
        A recording (CSV/NPZ/MAT, see ``rhmpc.sim.recordings``) to track instead of a scenario.
    data_read : dict
        How to read it: ``load_recording`` keywords ``var``, ``rows``, ``cols``, ``rate`` [Hz],
        ``units`` (MATLAB files), and ``point`` (from 1), the POI in a file of several tracked
        points (the others go to a multi-point predictor).
    train : tuple of str
        Recordings a predictor fitted before the run learns from (read as ``data``, the POI
        first), besides the run's own samples of its settling window.
    rr : str | None
        PhysioNet record whose beat annotations drive the heart phase: a shipped name
        (``mitdb-100``, ``1003``) or a path without extension.
    sensor : str
        Sensor model name (``rhmpc.sim.sensors.SENSORS``: the physical ``sonomicrometry`` by
        default, ``white``, ``ultrasound``, ``ideal``), or ``"recorded"`` to use a recording's
        samples as they are.
    sensor_settings : dict
        Keyword settings of the sensor model (SI units, ``rhmpc.sim.sensors.sensor_from_name``),
        among them ``playback``: how the samples reach the 2-kHz loop, ``"linear"`` (causal
        interpolation one raw period late, default), ``"hold"`` (causal zero-order hold) or
        ``"offline"`` (the non-causal interpolation of a
        prerecorded file, Tuna et al.'s protocol).
    predictor : str
        Predictor name (``rhmpc.predictors.PREDICTORS``), or ``"exact"`` for the true future.
    predictor_settings : dict
        Keyword settings passed to ``rhmpc.predictors.make_predictor``.
    predictor_params : dict
        The named parameter set each predictor runs with (``{"ekf": "tuna2013"}``: a paper's
        protocol, ``rhmpc.predictors.registry``), unless ``predictor_settings`` names one; the
        others take their default set.
    ground_truth : str
        What the error is measured against and what ``exact`` reads: ``"recorded"`` — the
        sensor's samples as recorded, linearly interpolated at the ticks (Tuna et al.'s
        protocol: the prerecorded data are the target, sensor errors and echo outliers
        included) — or ``"true"`` — the noise-free motion.
    seed : int
        Seed of the run's ``numpy.random.Generator`` (heart variability, sensor noise).
    loop, reference, mpc, plant, mismatch, observer
        Component settings (see their classes for units); ``plant`` holds the plant's physical
        quantities, each hardware effect an option (``--preset hardware``: Tuna's rig).
    faults
        Faults injected into the run (:class:`rhmpc.sim.sensors.faults.FaultSettings`): each starts
        within the run, and one with an end ends within it.
    """

    robot: str = "phantom"
    scenario: str = "fixed-a2-top"
    data: str | None = None
    data_read: dict = field(default_factory=dict)
    train: tuple[str, ...] = ()
    rr: str | None = None
    sensor: str = "sonomicrometry"
    sensor_settings: dict = field(default_factory=dict)
    predictor: str = "generalized"
    predictor_settings: dict = field(default_factory=dict)
    predictor_params: dict = field(default_factory=dict)
    ground_truth: str = "recorded"
    seed: int = 0
    loop: LoopSettings = field(default_factory=LoopSettings)
    reference: ReferenceSettings = field(default_factory=ReferenceSettings)
    mpc: MPCSettings = field(default_factory=MPCSettings)
    plant: PlantSettings = field(default_factory=PlantSettings)
    mismatch: ModelMismatch = field(default_factory=ModelMismatch)
    observer: ObserverSettings = field(default_factory=ObserverSettings)
    faults: FaultSettings = field(default_factory=FaultSettings)

    def __post_init__(self) -> None:
        if isinstance(self.train, list):  # as TOML reads it
            object.__setattr__(self, "train", tuple(self.train))
        for name, cls in SECTIONS.items():
            if not isinstance(getattr(self, name), cls):
                raise ValueError(f"{name} must be a {cls.__name__} (the table [{name}]), got "
                                 f"{getattr(self, name)!r}")
        for name, kind in TOP_LEVEL.items():
            value = getattr(self, name)
            if not _is(value, kind):
                raise ValueError(f"{name} must be {KIND_NAMES[kind]}, got {value!r}")
        if not all(isinstance(f, str) for f in self.train):
            raise ValueError(f"train must be a list of file names, got {self.train!r}")
        if not 0 <= self.seed < 2**63:
            raise ValueError(f"seed must be an integer in 0 … 2⁶³ − 1, got {self.seed!r}")
        if self.ground_truth not in GROUND_TRUTHS:
            raise ValueError(
                f"ground_truth must be one of {', '.join(GROUND_TRUTHS)}, got {self.ground_truth!r}"
            )
        self.faults.check(self.loop.duration)
        if self.sensor != "recorded":  # built once, unsampled: a bad setting fails here
            try:
                sensor_from_name(self.sensor, dim=3, **self.sensor_settings)
            except (TypeError, ValueError) as exc:
                raise ValueError(f"sensor {self.sensor!r}: {exc}") from None
        check_bounds(self)

    def predictor_keywords(self) -> dict[str, Any]:
        """The predictor's settings as :func:`rhmpc.predictors.registry.resolve` takes them:
        ``predictor_settings``, with the parameter set ``predictor_params`` names for this
        predictor unless ``predictor_settings`` names one."""
        settings = dict(self.predictor_settings)
        if self.predictor in self.predictor_params and "params" not in settings:
            settings["params"] = self.predictor_params[self.predictor]
        return settings

    def to_dict(self) -> dict[str, Any]:
        """TOML-ready nested dict (``None`` values left out, and the ``faults`` table when it
        injects none, so that a run's settings name only what it uses)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if (f.name == "faults" and value == FaultSettings()) or (
                    f.name == "train" and not value):
                continue
            if f.name in SECTIONS:
                out[f.name] = to_dict(value)
            elif value is not None:
                out[f.name] = (dict(value) if isinstance(value, dict)
                               else list(value) if isinstance(value, tuple) else value)
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "config") -> RunConfig:
        """Build from a nested dict; unknown keys raise ``UsageError`` naming the key."""
        names = {f.name for f in dataclasses.fields(cls)}
        kwargs: dict[str, Any] = {}
        for key, value in data.items():
            _refuse_old(key, value if isinstance(value, dict) else {}, where)
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
            elif key in FREE_TABLES:
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
            if not name:
                _refuse_old(key, value if isinstance(value, dict) else {})
            if name:
                nested.setdefault(section, {})[name] = value
            elif key in SECTIONS:  # a whole section: a table of its settings
                nested.setdefault(key, {}).update(_section_table(key, value))
            else:
                top[key] = value
        for section, values in nested.items():
            _refuse_old(section, values)
            if section in SECTIONS:
                _check_keys(section, SECTIONS[section], values)
                try:
                    top[section] = replace_settings(getattr(self, section), values)
                except (TypeError, ValueError) as exc:
                    raise UsageError(f"[{section}] {exc}") from None
            elif section in FREE_TABLES:
                top[section] = {**getattr(self, section), **values}
            else:
                valid = ", ".join([*SECTIONS, *FREE_TABLES])
                raise UsageError(f"unknown section {section!r} in {section}."
                                 f"{next(iter(values))}; valid sections: {valid}")
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(top) - names)
        if unknown:
            raise UsageError(f"unknown setting(s) {', '.join(unknown)}; valid: "
                             f"{', '.join(sorted(names))}")
        try:
            return dataclasses.replace(self, **top)
        except (TypeError, ValueError) as exc:
            raise UsageError(str(exc)) from None


def _section_table(section: str, value: Any) -> dict[str, Any]:
    """``value`` given for a whole section: its table, else a ``UsageError`` naming it."""
    if isinstance(value, dict):
        return value
    keys = ", ".join(f.name for f in dataclasses.fields(SECTIONS[section]))
    raise UsageError(f"{section} is a section of settings ({keys}), not a value: set one as "
                     f"{section}.KEY=VALUE, got {value!r}")


def run_config(file: str | Path | None = None, preset: str | None = None,
               options: dict[str, Any] | None = None, sets: Sequence[str] = (),
               faults: Sequence[str] = (), models: Sequence[str] = (),
               split: tuple[int, int] | None = None) -> RunConfig:
    """A run's settings from the command line, the one place its sources merge: the defaults,
    the TOML ``file`` (``--config``), the ``preset`` (:mod:`rhmpc.experiment.presets`), the
    command's ``options`` (top-level or dotted keys, ``{"predictor": "ekf", "loop.duration":
    5.0}``), then ``sets`` (``SECTION.KEY=VALUE``, the value in TOML's syntax: ``--set``), each
    over the ones before; ``faults`` (``--fault KIND@START…``) join the run's own, and
    ``split`` (TRAIN, END: ``--split``) sets the settling and the duration (:func:`with_split`).

    A recording among the options (``data``: a file, or a shipped recording's name, read with
    ``data_read``) makes the sensor ``recorded`` unless ``sensor`` is given and, without a
    ``file``, ``loop.duration`` or ``split``, the run as long as the recording; ``models`` are
    the saved models the predictor loads (:func:`rhmpc.experiment.fitting.model_settings`).
    The run must be scored on at least :data:`MIN_SCORED` seconds. A bad source is a one-line
    ``UsageError``.
    """
    from rhmpc.experiment.fitting import model_settings
    from rhmpc.sim.recordings.formats import found

    options = dict(options or {})
    if split is not None and {"loop.duration", "loop.settling"} & set(options):
        raise UsageError("--split TRAIN:END sets the settling and the duration: give neither "
                         "--settling nor --duration with it")
    missing = [f for f in options.get("train", ()) if not found(f)]
    if missing:
        raise UsageError(f"--train: no such file {', '.join(missing)}")
    recording = _recording(options, file is None, split) if options.get("data") else None
    config = load_config(file) if file else RunConfig()
    changes = {**preset_settings(preset), **options, **parse_sets(sets)}
    if faults:
        changes["faults.events"] = (*changes.get("faults.events", config.faults.events),
                                    *_checked_faults(faults))
    config = config.replace(**changes)
    if recording is not None and (config.data, config.data_read) != (options["data"],
                                                                      options["data_read"]):
        recording = None  # --set read another recording
    config = with_split(config, split, recording)
    if models:
        config = config.replace(**model_settings(config, models))
    check_scoring(config)
    return config


def _recording(options: dict[str, Any], whole: bool, split: tuple[int, int] | None):
    """Resolve the recording of ``options`` in place (its file, how it is read, the sensor
    that reads it as it is, and with ``whole`` and no duration or split, the run's length) and
    return it, read once (``None`` when nothing needs it read)."""
    from rhmpc.sim.recordings.formats import found
    from rhmpc.sim.recordings.shipped import SHIPPED, resolve

    read = dict(options.get("data_read", {}))
    point = read.pop("point", None)
    data, read, poi = resolve(options["data"], read)
    if not found(data):
        raise UsageError(f"{options['data']}: no such file (nor a shipped recording: "
                         f"{', '.join(SHIPPED)})")
    poi = point if point is not None else poi
    options.setdefault("sensor", "recorded")
    options["data"], options["data_read"] = data, {**read, **({} if poi is None else
                                                              {"point": poi})}
    if split is None and not (whole and "loop.duration" not in options):
        return None
    recording = _read(data, options["data_read"])
    if split is None:
        options["loop.duration"] = recording.duration
    return recording


def _read(data: str, read: dict):
    """The POI's recording of ``data`` (:func:`rhmpc.sim.sources.read_points`); an unreadable one is
    a ``UsageError``."""
    from rhmpc.sim.recordings import RecordingError
    from rhmpc.sim.sources import read_points

    try:
        return read_points(data, read)[0]
    except RecordingError as exc:
        raise UsageError(str(exc)) from None


def _checked_faults(specs: Sequence[str]) -> tuple[str, ...]:
    """``specs`` (``--fault``), each checked: a malformed one is a one-line error naming it."""
    for spec in specs:
        try:
            parse_fault(spec)
        except ValueError as exc:
            raise UsageError(f"--{exc}") from None
    return tuple(specs)


def parse_value(text: str):
    """A ``--set`` value: TOML scalar/array syntax (numbers, true/false, "strings", [lists])."""
    import tomllib

    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text  # a bare word is a string


def parse_sets(items: Sequence[str]) -> dict[str, Any]:
    """``SECTION.KEY=VALUE`` items (``--set``) as dotted settings (:func:`parse_value`)."""
    changes: dict[str, Any] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UsageError(f"--set {item!r}: expected SECTION.KEY=VALUE")
        changes[key.strip()] = parse_value(value.strip())
    return changes


def check_scoring(config: RunConfig) -> None:
    """A run must be scored on at least :data:`MIN_SCORED` seconds after settling."""
    loop = config.loop
    scored = loop.duration - loop.settling_s
    if scored < MIN_SCORED:
        raise UsageError(
            f"the run is scored on {scored:.3g} s after {loop.settling_s:.3g} s of settling; "
            f"at least {MIN_SCORED:g} s is needed (raise --duration or lower --settling)")


def with_split(config: RunConfig, split: tuple[int, int] | None,
               recording=None) -> RunConfig:
    """``config`` with its settling window and duration set by the literature's split (TRAIN,
    END) of its recording ``data`` [sample indices from 0]: the run starts at the first sample,
    its settling window (what a predictor fitted before the run learns from) ends at sample
    TRAIN, t_TRAIN − t_0, and it lasts t_END − t_0 (the recording's n/f when END = n), so that
    the scored instants are t_TRAIN ≤ t_k < t_END. ``recording``: ``data`` already read
    (:class:`rhmpc.sim.recordings.RecordedMotion`), else it is read here. Unchanged without a split;
    a split without a recording, or beyond it, is a one-line ``UsageError``."""
    if split is None:
        return config
    if config.data is None:
        raise UsageError("--split TRAIN:END splits a recording: it needs --data FILE")
    recording = _read(config.data, config.data_read) if recording is None else recording
    train, end = split
    n = recording.t.size
    if end > n:
        raise UsageError(f"--split {train}:{end}: {config.data} holds {n} samples (END <= {n})")
    t = recording.t - recording.t[0]
    duration = recording.duration if end == n else float(t[end])
    return config.replace(**{"loop.settling": float(t[train]), "loop.duration": duration})


def check_bounds(config: RunConfig) -> None:
    """Refuse the counts of a run that do not fit the bounds of :data:`rhmpc.io.BOUNDS`: the
    MPC's horizon (its memory, and its computing over the run's ticks)."""
    ticks = config.loop.duration / config.loop.Ts
    io.check("horizon", config.mpc.horizon, "mpc.horizon", time_scale=ticks)


#: Keys of earlier versions → the one line that names what replaced them.
RENAMED: dict[str, str] = {
    "plant.model": 'plant.model is now plant.kind ("arm" or "linear"); the hardware-like plant '
                   "is the arm with its effects on: --preset hardware",
    "plant.stiction_velocity": "plant.stiction_velocity is now plant.friction_smoothing [rad/s]",
    "hardware": "[hardware] is now part of [plant]: write plant.{key} (--preset hardware sets "
                "every value of Tuna's rig)",
}


def _refuse_old(section: str, values: dict[str, Any], where: str = "") -> None:
    """Raise ``UsageError`` with the new key of an earlier version's ``section`` or of its key
    in ``values`` (:data:`RENAMED`); nothing is reinterpreted."""
    prefix = f"{where}: " if where else ""
    if section == "hardware":
        key = next(iter(values), "KEY")
        raise UsageError(prefix + RENAMED["hardware"].format(key=key.partition(".")[0]))
    for key in values:
        if f"{section}.{key}" in RENAMED:
            raise UsageError(prefix + RENAMED[f"{section}.{key}"])


def _check_keys(section: str, cls: type, values: dict[str, Any]) -> None:
    """Raise ``UsageError`` listing the valid keys of ``[section]`` if ``values`` has others."""
    names = [f.name for f in dataclasses.fields(cls)]
    unknown = [k for k in values if k.partition(".")[0] not in names]
    if unknown:
        raise UsageError(f"unknown setting(s) {', '.join(f'{section}.{k}' for k in unknown)}; "
                         f"valid keys of [{section}]: {', '.join(names)}")


def read_toml(path: str | Path, kind: str = "config") -> dict[str, Any]:
    """A TOML file as a ``dict``, through the one reader (:func:`rhmpc.io.read_toml`: a
    regular file, bounded in size and depth); a file that cannot be read or parsed raises
    ``UsageError`` naming it."""
    try:
        return io.read_toml(path, kind)
    except FileError as exc:
        raise UsageError(str(exc)) from None


def load_config(path: str | Path) -> RunConfig:
    """Read a run's TOML file; errors name the file and the key."""
    return RunConfig.from_dict(read_toml(path), where=str(path))


def input_files(config: RunConfig) -> list[str]:
    """The files a run of ``config`` reads: its recording, its training recordings and its
    predictor's saved models (what no output of the run may replace)."""
    models = config.predictor_settings.get("models") or ()
    files = [config.data, *config.train, config.predictor_settings.get("model"),
             *(models if isinstance(models, list | tuple) else ())]
    return [f for f in files if isinstance(f, str)]


def save_config(config: RunConfig, path: str | Path) -> None:
    """Write ``config`` as TOML to ``path`` (atomically: :func:`rhmpc.io.write_text`)."""
    import tomli_w

    io.write_text(path, tomli_w.dumps(config.to_dict()))
