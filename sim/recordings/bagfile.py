"""ROS bags as recordings: rosbag2 (its folder, or its MCAP or SQLite 3 file) and ROS 1 ``.bag``,
read with the ``rosbags`` library (pure Python: no ROS install is needed).

One topic of the bag is the recording (``topic``, ``--topic``; a bag with one topic of a type
read needs none), of a type :mod:`rhmpc.sim.recordings.bagmsgs` reads. Its times are its
messages' header stamps (:mod:`rhmpc.sim.recordings.bagstamps`); its positions are in metres,
as ROS states them (REP 103), unless ``units`` (``--units``) says otherwise.

Before ``rosbags`` opens anything, the bag passes the one reader's rules
(:func:`check_bag`): a bag file is a regular file within the bound of a bag
(:data:`rhmpc.io.FILE_BYTES`); a bag's folder holds a ``metadata.yaml`` read through
:func:`rhmpc.io.read_text` (bounded in size, its nesting checked), and each storage file it names
is a regular file, in the folder, within the bound. A bag whose files are compressed whole
(rosbag2's ``compression_mode: file``) is refused: ``rosbags`` would decompress each to a
temporary copy of unbounded size. Every problem is a :class:`RecordingError` on one line naming
the bag; one about its topics names the topics it holds.
"""

from __future__ import annotations

import contextlib
import itertools
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path, PurePath

import numpy as np

from rhmpc import io
from rhmpc.io.reader import MAX_DEPTH, check_depth, text_depth
from rhmpc.sim.recordings.bagmsgs import TYPES, MessageType, frame_name, read_types, type_name
from rhmpc.sim.recordings.bagstamps import sample_times, stamp_problems
from rhmpc.sim.recordings.plausible import RecordingWarning
from rhmpc.sim.recordings.recorded import LENGTH_UNITS, RecordedMotion, RecordingError

#: The suffixes of a bag's file: ROS 1, rosbag2's MCAP and SQLite 3 storage.
BAG_SUFFIXES = (".bag", ".mcap", ".db3")
#: Each rosbag2 storage, by the name its metadata gives.
STORAGES = {"mcap": "MCAP", "sqlite3": "SQLite 3"}
#: At least this many samples make a recording [-].
MIN_SAMPLES = 2


def is_bag(path: str | Path) -> bool:
    """Whether ``path`` names a ROS bag: a ``.bag``, ``.mcap`` or ``.db3`` file, or a folder
    with a ``metadata.yaml`` or a storage file (a rosbag2 bag, or one whose recording was cut
    short before its metadata was written)."""
    path = Path(path)
    if path.suffix.lower() in BAG_SUFFIXES:
        return True
    return path.is_dir() and ((path / "metadata.yaml").exists() or bool(_storage_files(path)))


def _storage_files(path: Path) -> list[str]:
    """The names of (at most five of) the rosbag2 storage files in folder ``path``."""
    return sorted(itertools.islice((p.name for p in path.glob("*")
                                    if p.suffix in BAG_SUFFIXES[1:]), 5))


def check_bag(path: Path) -> str:
    """Refuse a bag the one reader's rules refuse (module docstring); return its format
    (``ROS 1 bag``, ``rosbag2 bag (MCAP)``, …)."""
    try:
        if path.is_dir():
            return _check_folder(path)
        io.open_input(path, "bag").close()
    except io.FileError as exc:
        raise RecordingError(str(exc)) from None
    suffix = path.suffix.lower()
    if suffix == ".bag":
        return "ROS 1 bag"
    return f"rosbag2 bag ({STORAGES['mcap' if suffix == '.mcap' else 'sqlite3']})"


def _check_folder(path: Path) -> str:
    meta = path / "metadata.yaml"
    if not meta.exists():
        found = _storage_files(path)
        hint = f": give its file, {path / found[0]}" if found else ""
        raise RecordingError(f"{path}: a rosbag2 folder without its metadata.yaml (a recording "
                             f"cut short?){hint}")
    info = _metadata(meta)
    if str(info.get("compression_mode") or "").lower() == "file":
        raise RecordingError(f"{path}: its files are compressed whole, which is not read; "
                             "convert it to an uncompressed bag first (ros2 bag convert)")
    files = info.get("relative_file_paths") or []
    for name in files if isinstance(files, list) else []:
        io.open_input(path / PurePath(str(name)).name, "bag").close()
    storage = str(info.get("storage_identifier"))
    return f"rosbag2 bag ({STORAGES.get(storage, storage)})"


def _metadata(meta: Path) -> dict:
    """A rosbag2 folder's ``rosbag2_bagfile_information``, its size and nesting bounded."""
    from ruamel.yaml import YAML

    text = io.read_text(meta, "bag metadata")
    if text_depth(text) > MAX_DEPTH:
        raise RecordingError(f"{meta}: nested deeper than {MAX_DEPTH} levels")
    try:
        data = YAML(typ="safe", pure=True).load(text)
    except Exception as exc:  # the YAML parser's errors, a recursion among them
        raise RecordingError(f"{meta}: not valid YAML ({_first_line(exc)})") from None
    info = data.get("rosbag2_bagfile_information") if isinstance(data, dict) else None
    if not isinstance(info, dict):
        raise RecordingError(f"{meta}: no rosbag2_bagfile_information, so no rosbag2 metadata")
    check_depth(info, str(meta))
    return info


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0]}" if text else type(exc).__name__


@contextlib.contextmanager
def rosbags_errors(path: Path) -> Iterator[None]:
    """Inside, what ``rosbags`` raises on a malformed bag is a :class:`RecordingError` naming
    ``path``."""
    try:
        yield
    except (RecordingError, MemoryError):
        raise
    except Exception as exc:  # rosbags parses the user's file: any failure is the file's
        raise RecordingError(f"{path}: not a readable ROS bag ({_first_line(exc)})") from None


@contextlib.contextmanager
def open_bag(path: Path):
    """The bag at ``path`` checked (:func:`check_bag`) and opened with ``rosbags``'
    ``AnyReader``: ``(reader, format)``. A bag that holds no message definitions is read with
    the latest ROS 2 types."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    kind = check_bag(path)
    with rosbags_errors(path):
        bag = AnyReader([path], default_typestore=get_typestore(Stores.LATEST))
        bag.open()
    try:
        yield bag, kind
    finally:
        with contextlib.suppress(Exception):
            bag.close()


def samples(path: Path, bag, connections) -> Iterator[tuple[str, int, list | None]]:
    """``(topic, receive time [ns], samples)`` of each message of ``connections`` in the order
    received: its samples (:mod:`rhmpc.sim.recordings.bagmsgs`), or None for a type not read."""
    with rosbags_errors(path):
        for conn, receive, raw in bag.messages(connections=connections):
            kind = TYPES.get(conn.msgtype)
            yield conn.topic, receive, (None if kind is None
                                        else kind.samples(bag.deserialize(raw, conn.msgtype)))


def topics_text(topics: dict) -> str:
    """The topics of a bag, each with its type and count of messages."""
    return ", ".join(f"{name} ({type_name(info.msgtype)}, {info.msgcount})"
                     for name, info in sorted(topics.items())) or "no topic"


def choose_topic(path: Path, topics: dict, topic: str | None) -> tuple[str, MessageType]:
    """The topic read and its type: ``topic`` (a leading ``/`` may be left out), or the only
    one of a type read; else a :class:`RecordingError` that names the bag's topics."""
    held = f"the bag holds {topics_text(topics)}"
    if topic is None:
        usable = [n for n, info in topics.items() if info.msgtype in TYPES and info.msgcount]
        if len(usable) != 1:
            why = ("name the POI's topic with --topic NAME" if usable
                   else f"no topic of a type read ({read_types()})")
            raise RecordingError(f"{path}: {why}; {held}")
        topic = usable[0]
    name = topic if topic in topics else f"/{topic}" if f"/{topic}" in topics else None
    if name is None:
        raise RecordingError(f"{path}: no topic {topic}; {held}")
    kind = TYPES.get(topics[name].msgtype)
    if kind is None:
        raise RecordingError(f"{path}: topic {name} is {type_name(topics[name].msgtype)}, which "
                             f"is not read (the types read: {read_types()}); {held}")
    if not topics[name].msgcount:
        raise RecordingError(f"{path}: topic {name} has no message; {held}")
    return name, kind


@dataclass
class Messages:
    """A topic's samples of one frame, in the order received: header stamps and receive times
    [ns], each sample's points [m]."""

    stamps: list[int] = field(default_factory=list)
    receive: list[int] = field(default_factory=list)
    points: list[list] = field(default_factory=list)


def collect(path: Path, bag, topic: str, connections) -> dict[str | None, Messages]:
    """The samples of ``topic`` by child frame (None for a type without frames), their count
    bounded as a recording's (:data:`rhmpc.io.BOUNDS`) as they are read."""
    limit, count = io.largest("samples"), 0
    out: dict[str | None, Messages] = {}
    for _, receive, items in samples(path, bag, connections):
        for child, stamp, points in items:
            m = out.setdefault(child, Messages())
            m.stamps.append(stamp)
            m.receive.append(receive)
            m.points.append(points)
            count += len(points)
        if count > limit:
            io.check("samples", count, f"{path} {topic}")
    return out


def read_bag(path: str | Path, topic: str | None = None, frame: str | None = None,
             units: str | None = None, points: bool = False) -> RecordedMotion:
    """One topic of a ROS bag as a recording (module docstring).

    Parameters
    ----------
    path : str or Path
        A rosbag2 folder, its ``.mcap`` or ``.db3`` file, or a ROS 1 ``.bag``.
    topic : str, optional
        The topic of the POI; optional in a bag with one topic of a type read.
    frame : str, optional
        The child frame of a ``tf2_msgs/TFMessage`` or ``TransformStamped`` topic; optional
        when the topic holds transforms to one frame only.
    units : str, optional
        The length unit of the positions when they are not in metres.
    points : bool
        Accept a topic of several tracked points, returned as (n, 3P).

    Returns
    -------
    RecordedMotion
        Times from the first header stamp [s], positions in metres (NaN where a message held
        fewer points than others), named ``PATH TOPIC`` (and ``[FRAME]``).
    """
    path = Path(path)
    with open_bag(path) as (bag, _):
        topics = bag.topics
        name, kind = choose_topic(path, topics, topic)
        if frame is not None and not kind.frames:
            raise RecordingError(f"{path}: --frame applies to tf2_msgs/TFMessage and "
                                 f"geometry_msgs/TransformStamped topics; {name} is {kind.name}")
        io.check("samples", topics[name].msgcount, f"{path} {name}")
        frames = collect(path, bag, name, topics[name].connections)
    child = _frame(path, name, frames, frame) if kind.frames else None
    where = f"{path} {name}" + (f" [{child}]" if child is not None else "")
    return _motion(where, frames.get(child) or Messages(), units, points)


def _frame(path: Path, topic: str, frames: dict, frame: str | None) -> str:
    """The child frame read: ``frame``, or the topic's only one."""
    held = ", ".join(sorted(f for f in frames if f is not None))
    if not frames:
        raise RecordingError(f"{path}: topic {topic} holds no transform")
    if frame is None and len(frames) == 1:
        return next(iter(frames))
    if frame is None:
        raise RecordingError(f"{path}: topic {topic} holds transforms to several frames: name "
                             f"one with --frame NAME ({held})")
    if frame_name(frame) not in frames:
        raise RecordingError(f"{path}: topic {topic} holds no transform to frame {frame} "
                             f"(it holds {held})")
    return frame_name(frame)


def _motion(where: str, m: Messages, units: str | None, points: bool) -> RecordedMotion:
    """The samples ``m`` as a recording in time order (:func:`sample_times`), warning about
    stamps reordered or left out."""
    width = max((len(p) for p in m.points), default=0)
    if width > 1 and not points:
        raise RecordingError(f"{where}: holds {width} tracked points; choose one with --poi N "
                             "(numbered from 1)")
    z = np.full((len(m.points), width, 3), np.nan)
    for i, p in enumerate(m.points):
        z[i, :len(p)] = p
    stamps = sample_times(np.array(m.stamps, dtype=np.int64), np.array(m.receive, dtype=np.int64))
    for text in stamp_problems(stamps, where):
        warnings.warn(text, RecordingWarning, stacklevel=4)
    if stamps.order.size < MIN_SAMPLES:
        raise RecordingError(f"{where}: {stamps.order.size} sample(s); at least {MIN_SAMPLES} "
                             "are needed")
    unit = "m" if units is None else units
    if unit not in LENGTH_UNITS:
        raise RecordingError(f"{where}: unknown units {unit!r} "
                             f"(use one of {', '.join(sorted(LENGTH_UNITS))})")
    z = z[stamps.order].reshape(stamps.order.size, -1) * LENGTH_UNITS[unit]
    return RecordedMotion(stamps.t, z, where, unit, "default" if units is None else "option",
                          "s")
