"""A ROS 2 node's side of DDS, with Cyclone DDS's Python binding and no ROS install.

ROS 2 on DDS (``rmw_cyclonedds_cpp``, the default of Humble's and Jazzy's alternatives) is
plain DDS under conventions, and :class:`Node` keeps them, so that a ROS 2 node sees ordinary
topics:

- a topic ``/a/b`` is the DDS topic ``rt/a/b``, its type ``PKG::msg::dds_::NAME_``
  (:mod:`rhmpc.runtime.ros2.names`, :mod:`rhmpc.runtime.ros2.messages`), its samples plain
  CDR (:mod:`rhmpc.runtime.ros2.cdr`);
- the domain is ``ROS_DOMAIN_ID``; Cyclone DDS reads its configuration from
  ``CYCLONEDDS_URI`` as a ROS 2 node does;
- the QoS are ROS 2's profiles: what a bridge reads it reads with the **sensor-data** profile
  (``rmw_qos_profile_sensor_data``: best effort, keep the last 5, volatile), which matches a
  publisher of either reliability and never waits for a stale sample's retransmission; what it
  publishes it publishes with the **default, reliable** profile (``rmw_qos_profile_default``:
  reliable, keep the last 10, volatile), which every subscriber matches, whichever reliability
  it asks for. Both announce plain CDR (XCDR1) only, as ROS 2 does.

This module imports ``cyclonedds`` (the ``ros2`` extra).
"""

from __future__ import annotations

from collections.abc import Callable

from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.core import Listener, Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

from rhmpc.runtime.ros2.cdr import CdrError
from rhmpc.runtime.ros2.messages import MESSAGES
from rhmpc.runtime.ros2.names import dds_topic, domain_id

__all__ = ["RELIABLE", "SENSOR_DATA", "Node"]

_PLAIN_CDR = Policy.DataRepresentation(use_cdrv0_representation=True)
#: ROS 2's sensor-data profile: best effort, keep last 5, volatile; plain CDR.
SENSOR_DATA = Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(5),
                  Policy.Durability.Volatile, _PLAIN_CDR)
#: ROS 2's default profile: reliable, keep last 10, volatile; plain CDR. A write blocks at most
#: 0.1 s for room in a full history (keep-last: never, in practice).
RELIABLE = Qos(Policy.Reliability.Reliable(max_blocking_time=duration(milliseconds=100)),
               Policy.History.KeepLast(10), Policy.Durability.Volatile, _PLAIN_CDR)
#: The DDS type names of the messages, to their ROS 2 names.
_ROS_TYPES = {t.__idl_typename__: name for name, t in MESSAGES.items()}


class _Deliver(Listener):
    """Hands each valid sample a reader takes to ``on_sample``, on Cyclone DDS's receive
    thread; bytes that hold no message are counted in ``malformed``."""

    def __init__(self, on_sample: Callable[[object], None]) -> None:
        super().__init__()
        self.on_sample, self.malformed = on_sample, 0

    def on_data_available(self, reader: DataReader) -> None:
        try:
            samples = reader.take(16)
        except CdrError:
            self.malformed += 1
            return
        for sample in samples:
            if getattr(sample, "sample_info", None) is not None and \
                    sample.sample_info.valid_data:
                self.on_sample(sample)


class Node:
    """One DDS participant on the ROS 2 domain, with the topics, publishers and subscriptions
    of one bridge.

    Parameters
    ----------
    domain : int or None
        The domain (None: ``ROS_DOMAIN_ID``, :func:`~rhmpc.runtime.ros2.names.domain_id`).
    """

    def __init__(self, domain: int | None = None) -> None:
        self.participant = DomainParticipant(domain_id() if domain is None else domain)
        self.topics: dict[str, Topic] = {}
        self.listeners: list[_Deliver] = []
        self.readers: list[DataReader] = []  # held: a reader lives as long as its node
        self._publications = BuiltinDataReader(self.participant, BuiltinTopicDcpsPublication)
        self._seen: dict[str, set[str]] = {}

    def _topic(self, name: str, message_type: type) -> Topic:
        if name not in self.topics:
            self.topics[name] = Topic(self.participant, dds_topic(name), message_type)
        return self.topics[name]

    def publisher(self, name: str, message_type: type) -> DataWriter:
        """A writer of ``message_type`` on the ROS 2 topic ``name`` (the reliable profile)."""
        return DataWriter(self.participant, self._topic(name, message_type), RELIABLE)

    def subscription(self, name: str, message_type: type,
                     on_sample: Callable[[object], None]) -> _Deliver:
        """Each sample of ``message_type`` on ``name`` to ``on_sample``, as it arrives (the
        sensor-data profile); returns the listener (its ``malformed`` count)."""
        deliver = _Deliver(on_sample)
        self.readers.append(DataReader(self.participant, self._topic(name, message_type),
                                       SENSOR_DATA, listener=deliver))
        self.listeners.append(deliver)
        return deliver

    def published_types(self, name: str) -> set[str]:
        """The ROS 2 types (``geometry_msgs/msg/PoseStamped``; the DDS name where it is none
        of :data:`~rhmpc.runtime.ros2.messages.MESSAGES`) of every publisher discovered on
        ``name`` so far."""
        for endpoint in self._publications.take(64):
            topic = getattr(endpoint, "topic_name", None)
            if topic is not None:
                self._seen.setdefault(topic, set()).add(
                    _ROS_TYPES.get(endpoint.type_name, endpoint.type_name))
        return set(self._seen.get(dds_topic(name), set()))
