"""ROS 2's names, domain and clock as the bridges use them; no ``cyclonedds`` here.

- **Names.** A ROS 2 topic ``/a/b`` is the DDS topic ``rt/a/b`` (ROS 2's ``rmw`` convention,
  REP 2005's mapping of names); a name's tokens are letters, digits and underscores, not
  starting with a digit, no ``__``, no empty token (ROS 2's name rules). A relative name is
  taken from the root namespace, as a node in ``/`` resolves it.
- **Domain.** ``ROS_DOMAIN_ID`` (0 … 232, default 0), as every ROS 2 node reads it; the DDS
  configuration (interfaces, discovery) is Cyclone DDS's own, ``CYCLONEDDS_URI``.
- **Clock.** A ROS 2 node stamps its messages with ROS time, the system clock
  (``CLOCK_REALTIME``, nanoseconds since the UNIX epoch) unless it runs on simulated time. The
  run's clock is ``CLOCK_MONOTONIC`` less the run's epoch. :class:`RosClock` maps one to the
  other through the offset between the two clocks, read afresh at each conversion (a step of
  the system clock moves the mapping with it): a stamp ``s`` is the instant
  ``s − (realtime − monotonic) − epoch`` on the run's clock.
"""

from __future__ import annotations

import importlib.util
import os
import re
import time

__all__ = ["NAMESPACE", "PREFIX", "RosClock", "dds_topic", "domain_id", "endpoint",
           "require_cyclonedds", "ros_name"]

#: What names a ROS 2 endpoint on the command line: ``ros2:NAME``.
PREFIX = "ros2:"
#: Where the bridges publish the run's forecast and status.
NAMESPACE = "/rhmpc"
#: ROS 2's largest domain id (its ports stay below 65 536).
MAX_DOMAIN = 232
_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def ros_name(name: str) -> str:
    """The absolute ROS 2 name of ``name`` (``a/b`` → ``/a/b``); ValueError naming the rule a
    name breaks."""
    absolute = name if name.startswith("/") else "/" + name
    tokens = absolute[1:].split("/")
    if absolute == "/" or not all(_TOKEN.fullmatch(t) for t in tokens) or "__" in absolute:
        raise ValueError(f"{name!r} is not a ROS 2 name (tokens of letters, digits and "
                         "underscores, each starting with a letter or an underscore, "
                         "separated by single slashes, no '__')")
    return absolute


def endpoint(value: str, option: str) -> str:
    """The ROS 2 name of an option's ``ros2:NAME``; ValueError on one line otherwise."""
    if not value.startswith(PREFIX):
        raise ValueError(f"{option} takes ros2:NAME (the only transport besides the "
                         f"deployment's own), got {value!r}")
    try:
        return ros_name(value[len(PREFIX):])
    except ValueError as exc:
        raise ValueError(f"{option}: {exc}") from None


def dds_topic(name: str) -> str:
    """The DDS topic of the ROS 2 topic ``name``: ``rt`` then its absolute name."""
    return "rt" + ros_name(name)


def domain_id(environ=os.environ) -> int:
    """The ROS 2 domain (``ROS_DOMAIN_ID``; 0 when unset); ValueError for another value than
    0 … :data:`MAX_DOMAIN`."""
    text = environ.get("ROS_DOMAIN_ID", "").strip() or "0"
    if not (text.isdigit() and int(text) <= MAX_DOMAIN):
        raise ValueError(f"ROS_DOMAIN_ID must be 0 … {MAX_DOMAIN}, got {text!r}")
    return int(text)


def require_cyclonedds() -> None:
    """ImportError on one line when the ``ros2`` extra is not installed (found, not
    imported: importing it takes a large part of a second)."""
    if importlib.util.find_spec("cyclonedds") is None:
        raise ImportError("the ROS 2 bridges need Cyclone DDS's Python binding: "
                          "pip install \"rhmpc[ros2]\"")


class RosClock:
    """ROS time (the system clock) against the run's clock (``CLOCK_MONOTONIC`` less
    ``epoch_ns``).

    Parameters
    ----------
    epoch_ns : int
        The run's epoch on ``CLOCK_MONOTONIC`` [ns].
    """

    def __init__(self, epoch_ns: int) -> None:
        self.epoch_ns = epoch_ns

    @staticmethod
    def offset_ns() -> int:
        """``CLOCK_REALTIME − CLOCK_MONOTONIC`` now [ns]: of three back-to-back readings, the
        one read in the least time (the least disturbed)."""
        best = None
        for _ in range(3):
            before = time.clock_gettime_ns(time.CLOCK_MONOTONIC)
            real = time.clock_gettime_ns(time.CLOCK_REALTIME)
            after = time.clock_gettime_ns(time.CLOCK_MONOTONIC)
            if best is None or after - before < best[0]:
                best = (after - before, real - (before + after) // 2)
        return best[1]

    def epoch_ros_ns(self) -> int:
        """The run's instant 0 in ROS time [ns since the UNIX epoch]."""
        return self.epoch_ns + self.offset_ns()

    def run_time(self, ros_ns: int) -> float:
        """The instant ``ros_ns`` (ROS time [ns]) on the run's clock [s], to the microsecond
        (the two clocks' offset, read afresh, varies by tens of nanoseconds)."""
        return round((ros_ns - self.epoch_ros_ns()) / 1000) * 1e-6

    def ros_time(self, seconds: float) -> int:
        """The instant ``seconds`` of the run's clock in ROS time [ns]."""
        return self.epoch_ros_ns() + round(seconds * 1e9)

    def now(self) -> float:
        """Now on the run's clock [s]."""
        return (time.clock_gettime_ns(time.CLOCK_MONOTONIC) - self.epoch_ns) * 1e-9
