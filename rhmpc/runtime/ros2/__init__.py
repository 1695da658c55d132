"""Bridges between a deployment and ROS 2, without a ROS install (the ``ros2`` extra).

A bridge is a process of the deployment in another part's place, so that the controller, the
predictor and the supervisor run unchanged: the **tracker bridge**
(:mod:`rhmpc.runtime.ros2.tracker`) in the sensor's place takes the samples of a ROS 2 topic
and publishes the forecasts and the run's status; the **console bridge**
(:mod:`rhmpc.runtime.ros2.console`) in the robot's place relays the controller's torques to an
arm over ROS 2 and its readings back. Between a bridge and the other parts runs the
deployment's authenticated wire (:mod:`rhmpc.runtime.wire`); between a bridge and ROS 2, DDS
as ROS 2 uses it (:mod:`rhmpc.runtime.ros2.dds`, :mod:`rhmpc.runtime.ros2.messages`,
:mod:`rhmpc.runtime.ros2.cdr`), with Cyclone DDS's Python binding.

Only the bridges' own modules import ``cyclonedds``, and only for a run that asks for a bridge:
:func:`tracker_part` and :func:`console_part` import them when called.
"""

from __future__ import annotations

from rhmpc.errors import UsageError
from rhmpc.runtime.ros2.names import require_cyclonedds, ros_name

__all__ = ["checked", "console_part", "report", "require", "taken", "tracker_part"]


def checked(tracker: str | None, console: str | None,
            allow_unauthenticated: bool) -> tuple[str | None, str | None]:
    """The bridges' absolute ROS 2 names (the tracker's topic, the console's namespace);
    ValueError on one line for a name that is not ROS 2's, or for a console without
    ``allow_unauthenticated``."""
    tracker, console = (None if n is None else ros_name(n) for n in (tracker, console))
    if console is not None and not allow_unauthenticated:
        raise ValueError(f"a console over ROS 2 ({console}) is not authenticated: any process "
                         "on its DDS domain can publish torques and readings (ROS 2 without "
                         "SROS2 has no authentication); accept that with "
                         "--allow-unauthenticated")
    return tracker, console


def require(*names: str | None) -> None:
    """:class:`~rhmpc.errors.UsageError` on one line when a bridge is asked for (a name not
    None) and the ``ros2`` extra is not installed."""
    if any(n is not None for n in names):
        try:
            require_cyclonedds()
        except ImportError as exc:
            raise UsageError(str(exc)) from None


def report(documents: dict) -> dict:
    """The bridges' part of a run's report: ``{"ros2": {"tracker": …, "console": …}}`` from
    the documents of the parts they replaced, or nothing without a bridge."""
    bridges = {part: documents[place]["ros2"] for part, place in (("tracker", "sensor"),
                                                                  ("console", "robot"))
               if "ros2" in documents[place]}
    return {"ros2": bridges} if bridges else {}


def tracker_part(topic: str | None) -> tuple | None:
    """The sensor's replacement for a tracker on ``topic``: (name, body, extra arguments), or
    None without one."""
    if topic is None:
        return None
    from rhmpc.runtime.ros2.tracker import tracker

    return ("tracker bridge", tracker, topic)


def console_part(namespace: str | None) -> tuple | None:
    """The robot's replacement for an arm under ``namespace``, or None without one."""
    if namespace is None:
        return None
    from rhmpc.runtime.ros2.console import console

    return ("console bridge", console, namespace)


def taken(folder, run) -> tuple:
    """The samples a tracker bridge sent in a run's ``folder``: (instants, POI) in the
    coordinates of ``run``'s recording (ValueError when it sent none)."""
    import numpy as np

    from rhmpc.runtime.ros2.tracker import taken as read

    return read(folder, int(np.size(run.truth.center)))
