"""The ROS 2 bridges' pieces: names, the clock, the messages' bytes against an independent
serializer, and the bridges' rules for samples and readings.

The bytes are compared with ``rosbags``' CDR serializer and its type stores of ROS 2 Humble and
Jazzy (an implementation that shares no code with ``cyclonedds`` nor with the bridges' codec),
for every message the bridges publish or read, on random values; the field names and types
with the stores' definitions.
"""

from __future__ import annotations

import dataclasses
import math
import time
import typing

import numpy as np
import pytest

from rhmpc.runtime.ros2.names import RosClock

cyclonedds = pytest.importorskip("cyclonedds", reason="the ROS 2 bridges need rhmpc[ros2]")
typesys = pytest.importorskip("rosbags.typesys", reason="the CDR comparison needs rosbags")

from cyclonedds.idl import IdlStruct  # noqa: E402

from rhmpc.runtime.ros2 import messages  # noqa: E402
from rhmpc.runtime.ros2.cdr import CdrError  # noqa: E402

STORES = {name: typesys.get_typestore(getattr(typesys.Stores, name))
          for name in ("ROS2_HUMBLE", "ROS2_JAZZY")}
#: What the bridges publish and read (the others are their parts).
TOP = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseArray", "nav_msgs/msg/Path",
       "sensor_msgs/msg/JointState", "diagnostic_msgs/msg/DiagnosticStatus")
#: rosbags' names of the IDL primitives.
ROSBAGS = {"int32": "int32", "uint32": "uint32", "float64": "float64", "byte": "byte"}


def _random(hint, rng: np.random.Generator):
    """A random value of a field of type ``hint`` (strings of 0 to 6 characters, some not
    ASCII; sequences of 0 to 4 elements)."""
    if hint is str:
        return "".join(rng.choice(list("abcXYZ_/09é")) for _ in range(rng.integers(0, 7)))
    if dataclasses.is_dataclass(hint):
        hints = typing.get_type_hints(hint, include_extras=True)
        return hint(*[_random(hints[f.name], rng) for f in dataclasses.fields(hint)])
    _, marker = typing.get_args(hint)
    if marker == "float64":
        return float(rng.normal(scale=10.0))
    if marker in ("int32", "uint32", "byte"):
        # byte: ROS 2's octet (0 … 255); rosbags packs it signed, so both agree on 0 … 127
        low, high = {"int32": (-2**31, 2**31), "uint32": (0, 2**32), "byte": (0, 128)}[marker]
        return int(rng.integers(low, high))
    return [_random(marker.subtype, rng) for _ in range(rng.integers(0, 5))]


def _rosbags(store, name: str, value):
    """``value`` (one of our messages) as rosbags' message of ``name``."""
    cls, (_, fields) = store.types[name], store.fielddefs[name]
    out = {}
    for field, (kind, spec) in fields:
        v = getattr(value, field)
        if kind.name == "NAME":
            out[field] = _rosbags(store, spec, v)
        elif kind.name == "SEQUENCE" and spec[0][0].name == "NAME":
            out[field] = [_rosbags(store, spec[0][1], e) for e in v]
        elif kind.name == "SEQUENCE" and spec[0][1][0] == "string":
            out[field] = list(v)
        elif kind.name == "SEQUENCE":
            out[field] = np.array(v, dtype=np.float64)
        else:
            out[field] = v
    return cls(**out)


@pytest.mark.parametrize("store", STORES)
@pytest.mark.parametrize("name", TOP)
def test_bytes_equal_rosbags(store: str, name: str) -> None:
    rng = np.random.default_rng(7)
    cls = messages.MESSAGES[name]
    for _ in range(20):
        value = _random(cls, rng)
        ours = value.serialize()
        theirs = bytes(STORES[store].serialize_cdr(_rosbags(STORES[store], name, value), name))
        assert ours == theirs
        assert ours == IdlStruct.serialize(value, use_version_2=False)  # cyclonedds' own
        assert cls.deserialize(theirs) == value


@pytest.mark.parametrize("store", STORES)
@pytest.mark.parametrize("name", list(messages.MESSAGES))
def test_fields_are_ros2s(store: str, name: str) -> None:
    """Each field's name and type as the store defines the message."""
    cls = messages.MESSAGES[name]
    hints = typing.get_type_hints(cls, include_extras=True)
    _, theirs = STORES[store].fielddefs[name]
    assert [f.name for f in dataclasses.fields(cls)] == [f for f, _ in theirs]
    for field, (kind, spec) in theirs:
        hint = hints[field]
        if kind.name == "NAME":
            assert messages.message_name(hint) == spec
        elif kind.name == "BASE":
            assert (hint is str and spec[0] == "string") or \
                ROSBAGS[typing.get_args(hint)[1]] == spec[0]
        else:
            element = typing.get_args(hint)[1].subtype
            assert spec[0][1] in ((messages.message_name(element),) if
                                  dataclasses.is_dataclass(element) else
                                  (("string", 0),) if element is str else
                                  ((typing.get_args(element)[1], 0),))
    assert cls.__idl_typename__ == "{}::msg::dds_::{}_".format(*name.split("/msg/"))


def test_bad_bytes_are_one_error() -> None:
    good = messages.JointState(name=["a"], position=[1.0]).serialize()
    for bad in (good[:-3], b"\x00\x00\x00\x00" + good[4:],
                good[:4] + b"\x00" * 8 + b"\xff\xff\xff\x7f" + good[16:]):
        with pytest.raises(CdrError):
            messages.JointState.deserialize(bad)


def test_the_profiles_announce_plain_cdr() -> None:
    from cyclonedds.core import Policy

    from rhmpc.runtime.ros2.dds import RELIABLE, SENSOR_DATA

    for qos in (RELIABLE, SENSOR_DATA):
        assert qos[Policy.DataRepresentation] == Policy.DataRepresentation(
            use_cdrv0_representation=True)
    assert SENSOR_DATA[Policy.Reliability] == Policy.Reliability.BestEffort
    assert SENSOR_DATA[Policy.History] == Policy.History.KeepLast(5)
    assert RELIABLE[Policy.History] == Policy.History.KeepLast(10)


# -- the bridges' rules ---------------------------------------------------------------


class _Link:
    """What a bridge sends, kept."""

    def __init__(self, clock: RosClock) -> None:
        self.clock, self.sent = clock, []

    def now(self) -> float:
        return self.clock.now()

    def send(self, ports, kind, stamp, values, origin=math.nan, period=0.0) -> None:
        self.sent.append((ports, kind, stamp, np.array(values)))


def _role(ticks: int = 20_000):
    from rhmpc.runtime import processes
    from rhmpc.runtime.wire import Bounds

    # stamps up to 1 s ahead: the readings below are put on ticks to come, whatever the pace
    bounds = Bounds((1.0, 1.0, 1.0), (-1.0, -1.0, -1.0), (1.0, 1.0, 1.0), (0.0, 0.0, 0.05),
                    ahead=1.0)
    epoch = time.clock_gettime_ns(time.CLOCK_MONOTONIC) - 1_000_000_000  # 1 s into the run
    return processes.Role(epoch, ticks, 0.5e-3, processes.Ports(1, 2, 3), None, b"k" * 32,
                          bounds)


def _header(clock: RosClock, t: float | None) -> messages.Header:
    return messages.Header(messages.time_of(0 if t is None else clock.ros_time(t)), "tracker")


def test_samples_are_stamped_checked_and_filled() -> None:
    from rhmpc.runtime.ros2.tracker import Samples

    role = _role()
    clock = RosClock(role.epoch_ns)
    link = _Link(clock)
    samples = Samples(link, role, clock, dt=0.04, poi=1, others=True)
    now = clock.now()
    near = [0.0, 0.001, 0.05]
    pose = messages.PoseStamped(_header(clock, now - 0.2), messages.pose_at(near))
    samples.take(pose)
    assert link.sent[-1][1:3] == ("measured_cp", pytest.approx(now - 0.2, abs=1e-6))
    samples.take(messages.PoseStamped(_header(clock, now - 0.2), messages.pose_at(near)))
    samples.take(messages.PoseStamped(_header(clock, now + 2.0), messages.pose_at(near)))
    samples.take(messages.PoseStamped(_header(clock, now - 0.1), messages.pose_at([0, 0, 1])))
    array = messages.PoseArray(_header(clock, now - 0.08),
                               [messages.pose_at([0.0, 0.0, 0.04]), messages.pose_at(near),
                                messages.pose_at([math.nan, 0.0, 0.0])])
    samples.take(array)  # 0.12 s after the last: two missing samples first, then the POI first
    assert [s[3].shape for s in link.sent[1:]] == [(1, 3), (1, 3), (3, 3)]
    assert np.isnan(link.sent[1][3]).all() and np.isnan(link.sent[3][3][2]).all()
    np.testing.assert_array_equal(link.sent[3][3][:2], [near, [0.0, 0.0, 0.04]])
    samples.take(messages.PoseArray(_header(clock, None), [messages.pose_at(near)]))
    assert samples.dropped == {"stamp": 1, "order": 1, "before_start": 0, "no_poi": 1,
                               "implausible": 1}
    assert samples.sent == 4 and len(samples.taken) == 2


def test_readings_are_put_on_their_tick() -> None:
    from rhmpc.runtime.ros2.console import Readings

    role = _role()
    clock = RosClock(role.epoch_ns)
    link = _Link(clock)
    readings = Readings(link, role, clock, ["yaw", "shoulder", "elbow"], late=40)
    tick = math.ceil(clock.now() / role.Ts) + 600  # 0.3 s ahead

    def at(k: int, names: list[str], q: list[float]) -> messages.JointState:
        return messages.JointState(_header(clock, k * role.Ts + 1e-4), names, q)

    readings.take(at(tick, ["jaw", "elbow", "yaw", "shoulder"], [9.0, 0.3, 0.1, 0.2]))
    assert link.sent[-1][1:3] == ("measured_js", pytest.approx(tick * role.Ts))
    np.testing.assert_array_equal(link.sent[-1][3], [[0.1, 0.2, 0.3]])
    np.testing.assert_array_equal(readings.q[tick - 1], [0.1, 0.2, 0.3])
    readings.take(at(tick, [], [0.1, 0.2, 0.3]))  # the same tick again
    readings.take(at(400, [], [0.1, 0.2, 0.3]))  # 0.2 s: passed
    readings.take(at(tick + 1, ["yaw"], [0.1]))  # joints missing
    readings.take(at(tick + 2, [], [0.1, 0.2, 9.0]))  # beyond the limits
    readings.take(at(tick + 3, [], [0.1, 0.2, 0.3]))
    assert readings.dropped == {"joints": 1, "before_start": 0, "passed": 1, "order": 1,
                                "implausible": 1}
    assert readings.sent == 2
    late = Readings(link, role, clock, ["yaw", "shoulder", "elbow"], late=40)
    now = math.floor(clock.now() / role.Ts)
    late.take(at(now - 60, [], [0.1, 0.2, 0.3]))  # 30 ms late: past the observer's window
    late.take(at(now - 10, [], [0.1, 0.2, 0.3]))  # 5 ms late: the controller fuses it late
    assert late.dropped["passed"] == 1 and late.sent == 1
    assert link.sent[-1][2] == pytest.approx((now - 10) * role.Ts)
    fresh = Readings(link, role, clock, ["yaw", "shoulder", "elbow"], late=40)
    before = clock.now()
    fresh.take(messages.JointState(_header(clock, None), [], [0.1, 0.2, 0.3]))
    after = clock.now()  # unstamped: the tick after its arrival, which lies between the two
    assert before <= link.sent[-1][2] <= after + role.Ts


def test_joint_names_follow_the_controllers_order() -> None:
    from rhmpc.robots import load_robot
    from rhmpc.runtime.ros2.console import joint_names

    assert joint_names(load_robot("phantom")) == ["yaw", "shoulder", "elbow"]
