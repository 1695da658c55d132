"""`load_robot(name)`: a registered robot by its name, or any robot by its file.

Each registered robot is a robot file shipped in ``robots/urdf`` (``phantom.toml``, ...), the
same kind of file a user writes for an arm of their own (:mod:`rhmpc.robots.description`), so there
is one way to describe a robot.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from rhmpc.robots.description import robot_from_file
from rhmpc.robots.model import Robot

#: Registered robot names (each ``robots/urdf/NAME.toml``).
ROBOTS: tuple[str, ...] = ("phantom", "phantom-cavusoglu", "finger_edu", "ur5")


def urdf_path(filename: str) -> str:
    """Path of a file shipped in ``robots/urdf`` (works from an installed wheel too)."""
    ref = resources.files("rhmpc.robots") / "urdf" / filename
    if not ref.is_file():
        raise FileNotFoundError(
            f"robot description {filename!r} is not installed with 'rhmpc.robots'")
    return str(ref)


def is_robot_file(name: str) -> bool:
    """Whether ``name`` names a robot file rather than a registered robot."""
    return name.endswith(".toml") or "/" in name or Path(name).suffix != ""


def load_robot(name: str) -> Robot:
    """A registered robot (``ROBOTS``) or the robot of a file ``*.toml``
    (:func:`rhmpc.robots.description.robot_from_file`).

    Raises
    ------
    ValueError
        If ``name`` is neither (the message lists the valid names), or the file does not
        describe a robot (:class:`rhmpc.robots.description.RobotFileError`, naming the key).
    """
    if name in ROBOTS:
        return robot_from_file(urdf_path(f"{name}.toml"))
    if is_robot_file(name):
        return robot_from_file(name)
    raise ValueError(f"unknown robot {name!r}; valid robots: {', '.join(ROBOTS)}, or a robot "
                     "file FILE.toml")
