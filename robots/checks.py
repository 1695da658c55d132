"""What a robot file's numbers must be, and what the arm they describe must do at home.

A robot file's numbers are TOML's numbers (an integer or a float: a boolean and text are not),
each within the range of an arm (:data:`RANGES`: a value beyond it is a unit error or a typo,
and would overflow the controller's arithmetic). The arm they build must hold its home
posture: a mass matrix M(q₀) positive definite and not far off (:data:`MAX_MASS_CONDITION`), the
gravity torque g(q₀) within the torque limits, a tool's Jacobian regular there
(:data:`MAX_CONDITION`), and the POI's cube within reach. Each problem raises
:class:`RobotFileError` naming the key.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from rhmpc.robots.model import Robot

__all__ = ["MAX_CONDITION", "MAX_MASS_CONDITION", "RANGES", "RobotFileError", "check_home",
           "floats", "is_number", "listed", "number", "vector"]

#: A home posture whose Jacobian's singular values differ by more than this is singular.
MAX_CONDITION = 1e3
#: A mass matrix at home whose eigenvalues differ by more than this holds a mass or an inertia
#: far off: the registered arms' differ by at most about 10² (their bodies weigh grams to kg).
MAX_MASS_CONDITION = 1e8
#: The range of each of a robot file's numbers that describes an arm [SI units]; a value
#: beyond it is a unit error or a typo, and would overflow the controller's arithmetic. The
#: largest industrial arms' joint torques are about 10⁴ N·m and their gear ratios 10³; a
#: motor's rotor holds at most about 10⁻² kg·m²; the finest encoders count 2³² a turn; Earth's
#: surface gravity is 9.78–9.83 m/s² (twice it leaves room for a rounded or a test value and
#: refuses 981 cm/s²); a heart moves less than 30 mm (``workspace``).
RANGES: dict[str, tuple[float, float]] = {
    "torque_limits": (0.0, 1e5), "armature": (0.0, 1e3), "friction": (0.0, 1e5),
    "damping": (0.0, 1e5), "gravity": (0.0, 20.0), "workspace": (0.0, 1.0),
    "encoder_resolution": (1e-13, 1.0), "gear_ratio": (0.0, 1e4), "peak_torque": (0.0, 1e3),
    "torque_constant": (0.0, 1e2), "no_load_current": (0.0, 1e3), "rotor_inertia": (0.0, 1.0),
    "encoder_counts": (1.0, 2.0**32),
}


class RobotFileError(ValueError):
    """A robot file that cannot describe a robot; the message names the file and the key."""


def is_number(value) -> bool:
    """Whether ``value`` is a number of TOML (an integer or a float: not a bool, not text)."""
    return isinstance(value, int | float) and not isinstance(value, bool)


def floats(value, shape: tuple[int, ...]) -> np.ndarray | None:
    """``value`` (nested lists) as floats of ``shape`` when each entry is a number (not a
    bool, not text), else None."""
    try:
        a = np.asarray(value, dtype=object)
    except (TypeError, ValueError):
        return None
    if a.shape != shape or not all(is_number(v) for v in a.flat):
        return None
    return a.astype(float)


def _within(v: np.ndarray, key: str, positive: bool) -> bool:
    """Whether the finite numbers ``v`` lie in ``key``'s :data:`RANGES` (> 0 with
    ``positive``)."""
    lo, hi = RANGES.get(key, (-math.inf, math.inf))
    return bool(np.all(np.isfinite(v)) and np.all(v >= lo) and np.all(v <= hi)
                and not (positive and np.any(v <= 0)))


def _wanted(what: str, key: str, positive: bool) -> str:
    """What ``key`` takes, in words: "3 finite numbers in (0, 1e+05]"."""
    lo, hi = RANGES.get(key, (None, None))
    if lo is None:
        return what + (" > 0" if positive else "")
    return f"{what} in {'(' if positive and lo == 0 else '['}{lo:g}, {hi:g}]"


def vector(doc: dict, key: str, n: int, positive: bool = False, default=None) -> np.ndarray:
    """``doc[key]`` as n finite numbers in ``key``'s range (> 0 with ``positive``); booleans
    and text are not numbers."""
    value = doc.get(key, default)
    v = floats(value, (n,))
    if v is None or not _within(v, key, positive):
        shown = value.tolist() if isinstance(value, np.ndarray) else value
        origin = "" if key in doc else " (not given: the URDF's or the drives'; give it)"
        raise RobotFileError(f"{key}: must be {_wanted(f'{n} finite numbers', key, positive)}, "
                             f"got {shown!r}{origin}")
    return v


def number(table: dict, key: str, where: str = "") -> float:
    """``table[key]``: a finite number > 0 in ``key``'s range."""
    value = table.get(key)
    if not is_number(value) or not _within(np.float64(value), key, True):
        raise RobotFileError(f"{where}{key}: must be "
                             f"{_wanted('a finite number', key, True)}, got {value!r}")
    return float(value)


def _check_dynamics(robot: Robot) -> None:
    """At home, the mass matrix M(q₀) positive definite and the gravity torque g(q₀) within
    the torque limits: an arm that holds its home posture."""
    M = robot.mass_matrix(robot.q0)
    eigenvalues = np.linalg.eigvalsh(M) if np.all(np.isfinite(M)) else np.full(3, np.nan)
    if not eigenvalues[0] > 0:
        raise RobotFileError(f"urdf: the mass matrix at home is not positive definite "
                             f"(eigenvalues {listed(eigenvalues)} kg·m²): the links the "
                             "joints move need masses and inertias")
    if eigenvalues[-1] > MAX_MASS_CONDITION * eigenvalues[0]:
        raise RobotFileError(f"urdf: the mass matrix at home has eigenvalues "
                             f"{listed(eigenvalues)} kg·m², more than "
                             f"{MAX_MASS_CONDITION:.0e} apart: a mass or an inertia of the URDF "
                             f"is far off ({_masses(robot)})")
    data = robot.create_data()
    gravity = pin.computeGeneralizedGravity(robot.model, data, robot.q0)
    over = np.abs(gravity) > robot.torque_limit
    if np.any(over):
        j = int(np.flatnonzero(over)[0])
        raise RobotFileError(
            f"home: holding the home posture against gravity takes {abs(gravity[j]):.4g} N·m "
            f"at joint {robot.model.names[j + 1]!r}, beyond its torque limit "
            f"{robot.torque_limit[j]:.4g} N·m; check the URDF's masses ({_masses(robot)}), "
            f"gravity ({-robot.model.gravity.linear[2]:.4g} m/s²) and torque_limits")


def listed(values) -> str:
    """Numbers in a message, to 4 significant digits."""
    return ", ".join(f"{v:.4g}" for v in values)


def _masses(robot: Robot) -> str:
    """The moving bodies' masses in a message: their sum and the heaviest."""
    inertias = list(robot.model.inertias)[1:]
    j = int(np.argmax([i.mass for i in inertias]))
    return (f"{sum(i.mass for i in inertias):.4g} kg in all, {inertias[j].mass:.4g} kg moved "
            f"by joint {robot.model.names[j + 1]!r}")


def check_home(robot: Robot, workspace: float) -> None:
    """The home posture regular (within the limits: :class:`Robot` checks it), the arm able
    to hold it (:func:`_check_dynamics`), and the POI's cube within reach."""
    _check_dynamics(robot)
    sv = np.linalg.svd(robot.ee_jacobian(robot.q0), compute_uv=False)
    if not sv[-1] > sv[0] / MAX_CONDITION:
        raise RobotFileError(f"home: the tool's Jacobian is singular there (singular values "
                             f"{sv.round(6).tolist()} m/rad)")
    y0 = robot.ee_position(robot.q0)
    for axis, sign in ((a, s) for a in range(3) for s in (1.0, -1.0)):
        point = y0 + sign * workspace * np.eye(3)[axis]
        distance, _ = robot.distance_to_reach(point)
        if distance > 1e-4:
            raise RobotFileError(
                f"workspace: the tool cannot reach {1e3 * workspace:g} mm along "
                f"{'+' if sign > 0 else '-'}{'xyz'[axis]} of its home position within the "
                f"joint limits (short by {1e3 * distance:.1f} mm); move home or reduce "
                "workspace")
