"""A run's configuration: every setting of a closed-loop run, and its TOML file."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import boundary
from boundary import FileError
from rhmpc.control.cancellation import ModelMismatch
from rhmpc.control.observer import ObserverSettings
from rhmpc.control.reference import ReferenceSettings
from rhmpc.control.settings import MPCSettings
from rhmpc.errors import UsageError
from rhmpc.experiment.tables import from_dict, replace_settings, to_dict
from sim.loop import LoopSettings
from sim.plant import HardwareSettings, PlantSettings
from sim.sensors.faults import FaultSettings

#: Sections of a run's TOML file and the settings class each one builds.
SECTIONS: dict[str, type] = {
    "loop": LoopSettings,
    "reference": ReferenceSettings,
    "mpc": MPCSettings,
    "plant": PlantSettings,
    "mismatch": ModelMismatch,
    "observer": ObserverSettings,
    "hardware": HardwareSettings,
    "faults": FaultSettings,
}


GROUND_TRUTHS: tuple[str, ...] = ("recorded", "true")

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
        A recording (CSV/NPZ/MAT, see ``sim.recordings``) to track instead of a scenario.
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
    predictor_params : dict
        The named parameter set each predictor runs with (``{"ekf": "tuna2013"}``: a paper's
        protocol, ``predictors.registry``), unless ``predictor_settings`` names one; the
        others take their default set.
    ground_truth : str
        What the error is measured against and what ``exact`` reads: ``"recorded"`` — the
        sensor's samples as recorded, linearly interpolated at the ticks (Tuna et al.'s
        protocol: the prerecorded data are the target, sensor errors and echo outliers
        included) — or ``"true"`` — the noise-free motion.
    seed : int
        Seed of the run's ``numpy.random.Generator`` (heart variability, sensor noise).
    loop, reference, mpc, plant, mismatch, observer, hardware
        Component settings (see their classes for units); ``hardware`` applies when
        ``plant.model = "hardware"``.
    faults
        Faults injected into the run (:class:`sim.sensors.faults.FaultSettings`): each starts
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
    hardware: HardwareSettings = field(default_factory=HardwareSettings)
    faults: FaultSettings = field(default_factory=FaultSettings)

    def __post_init__(self) -> None:
        if isinstance(self.train, list):  # as TOML reads it
            object.__setattr__(self, "train", tuple(self.train))
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
        check_bounds(self)

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
            if name:
                nested.setdefault(section, {})[name] = value
            else:
                top[key] = value
        for section, values in nested.items():
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


def with_split(config: RunConfig, split: tuple[int, int] | None) -> RunConfig:
    """``config`` with its settling window and duration set by the literature's split (TRAIN,
    END) of its recording ``data`` [sample indices from 0]: the run starts at the first sample,
    its settling window (what a predictor fitted before the run learns from) ends at sample
    TRAIN, t_TRAIN − t_0, and it lasts t_END − t_0 (the recording's n/f when END = n), so that
    the scored instants are t_TRAIN ≤ t_k < t_END. Unchanged without a split; a split without a
    recording, or beyond it, is a one-line ``UsageError``."""
    if split is None:
        return config
    if config.data is None:
        raise UsageError("--split TRAIN:END splits a recording: it needs --data FILE")
    from sim.recordings import RecordingError
    from sim.sources import read_points

    try:
        recording, _ = read_points(config.data, config.data_read)
    except RecordingError as exc:
        raise UsageError(str(exc)) from None
    train, end = split
    n = recording.t.size
    if end > n:
        raise UsageError(f"--split {train}:{end}: {config.data} holds {n} samples (END <= {n})")
    t = recording.t - recording.t[0]
    duration = recording.duration if end == n else float(t[end])
    return config.replace(**{"loop.settling": float(t[train]), "loop.duration": duration})


def check_bounds(config: RunConfig) -> None:
    """Refuse the counts of a run that do not fit the bounds of :data:`boundary.BOUNDS`: the
    MPC's horizon (its memory, and its computing over the run's ticks)."""
    ticks = config.loop.duration / config.loop.Ts
    boundary.check("horizon", config.mpc.horizon, "mpc.horizon", time_scale=ticks)


def _check_keys(section: str, cls: type, values: dict[str, Any]) -> None:
    """Raise ``UsageError`` listing the valid keys of ``[section]`` if ``values`` has others."""
    names = [f.name for f in dataclasses.fields(cls)]
    unknown = [k for k in values if k.partition(".")[0] not in names]
    if unknown:
        raise UsageError(f"unknown setting(s) {', '.join(f'{section}.{k}' for k in unknown)}; "
                         f"valid keys of [{section}]: {', '.join(names)}")


def read_toml(path: str | Path, kind: str = "config") -> dict[str, Any]:
    """A TOML file as a ``dict``, through the one reader (:func:`boundary.read_toml`: a
    regular file, bounded in size and depth); a file that cannot be read or parsed raises
    ``UsageError`` naming it."""
    try:
        return boundary.read_toml(path, kind)
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
    """Write ``config`` as TOML to ``path`` (atomically: :func:`boundary.write_text`)."""
    import tomli_w

    boundary.write_text(path, tomli_w.dumps(config.to_dict()))
