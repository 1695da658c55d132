"""Bridges between a deployment and ROS 2, without a ROS install (the ``ros2`` extra).

A bridge is a process of the deployment in another part's place, so that the controller, the
predictor and the supervisor run unchanged: the **tracker bridge**
(:mod:`.tracker`) in the sensor's place takes the samples of a ROS 2 topic and publishes the
forecasts and the run's status; the **console bridge** (:mod:`.console`) in the robot's place
relays the controller's torques to an arm over ROS 2 and its readings back. Between a bridge
and the other parts runs the deployment's authenticated wire (:mod:`rhmpc.runtime.wire`);
between a bridge and ROS 2, DDS as ROS 2 uses it (:mod:`.dds`, :mod:`.messages`, :mod:`.cdr`),
with Cyclone DDS's Python binding.

Only the bridges' own modules import ``cyclonedds``, and only for a run that asks for a bridge:
:func:`tracker_part` and :func:`console_part` import them when called.
"""

from __future__ import annotations

__all__ = ["console_part", "taken", "tracker_part"]


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
