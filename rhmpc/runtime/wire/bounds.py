"""What a receiver takes as plausible: the bounds of each kind's values and stamps.

An authenticated message may still be wrong (a part's fault, a tracker's glitch): every
receiver checks, before it uses one, that

- its values are finite (a row of NaN in a ``measured_cp``: a point not tracked);
- a torque lies within the arm's torque limits, a joint reading within its limits widened by
  :attr:`Bounds.joint_margin`;
- the POI's sample or a forecast lies within :attr:`Bounds.radius` of the POI's registration
  (the tracker's point the controller is placed with), the other tracked points within
  :data:`OTHERS` radii of it;
- its ``stamp`` and ``sent`` lie between :attr:`Bounds.max_age` before the receiver's clock
  and :attr:`Bounds.ahead` after it;
- a forecast's period is the one expected.

The limits come from the robot file (:class:`rhmpc.robots.Robot`), the registration from the
run; the C programs apply the same bounds (their command line, ``rhmpc_wire.h``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rhmpc.runtime.wire.codec import Message

__all__ = ["OTHERS", "WORKSPACE_RADIUS", "Bounds"]

#: The default radius of plausible samples around the POI's registration [m]. The heart's
#: surface travels 10–15 mm peak to peak with each beat (Tuna et al. 2013, Table I's
#: sonomicrometry; Yuen et al. 2009: about 20 mm of mitral annulus travel) and breathing adds
#: a drift of the same order: 50 mm holds every beat with a wide margin and nothing a metre off.
WORKSPACE_RADIUS = 0.05
#: The other tracked points of a ``measured_cp`` may lie this many radii from the registration
#: (0.5 m by default: markers elsewhere on the heart or the chest, within a tracker's view).
OTHERS = 10.0


@dataclass(frozen=True)
class Bounds:
    """The bounds a receiver checks (SI units).

    Attributes
    ----------
    torque_max : tuple of float
        Each joint's torque limit [N·m].
    joint_lower, joint_upper : tuple of float
        Each joint's position limits [rad].
    center : tuple of float
        The POI's registration: the tracker's point placed at the tool's home [m].
    radius : float
        How far from ``center`` a sample or a forecast may lie [m].
    joint_margin : float
        How far beyond its limits a joint reading may lie [rad] (encoder noise, a limit met
        at speed).
    max_age : float
        The oldest stamp taken, before the receiver's clock [s] (the controller's latency cap).
    ahead : float
        The latest stamp taken, after the receiver's clock [s]: clock skew and the next tick's
        reading, which the robot stamps with that tick.
    period : float or None
        A forecast's period [s]; None: any finite positive one.
    """

    torque_max: tuple[float, ...]
    joint_lower: tuple[float, ...]
    joint_upper: tuple[float, ...]
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float = WORKSPACE_RADIUS
    joint_margin: float = 0.1
    max_age: float = 0.25
    ahead: float = 2e-3
    period: float | None = None

    def __post_init__(self) -> None:
        n = len(self.torque_max)
        if not (len(self.joint_lower) == len(self.joint_upper) == n and len(self.center) == 3):
            raise ValueError("torque_max, joint_lower and joint_upper need one value per joint, "
                             "center three")
        for name in ("radius", "joint_margin", "max_age", "ahead"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")

    @property
    def joints(self) -> int:
        return len(self.torque_max)

    def problem(self, message: Message, now: float) -> str | None:
        """Why ``message`` is implausible at ``now`` on the receiver's clock [s], or None."""
        for name, t in (("stamp", message.stamp), ("sent", message.sent)):
            if not (now - self.max_age <= t <= now + self.ahead):
                return f"{name} {t:.6g} s outside [{now - self.max_age:.6g}, " \
                       f"{now + self.ahead:.6g}] s"
        return getattr(self, f"_{message.kind}")(message)

    def _measured_cp(self, message: Message) -> str | None:
        rows = message.values
        tracked = np.isfinite(rows).all(axis=1)
        if not (tracked | np.isnan(rows).all(axis=1)).all():
            return "a point partly tracked or infinite"
        others = rows[1:][tracked[1:]]  # the other tracked points: within a tracker's field
        return self._near(rows[:1][tracked[:1]]) or self._near(others, OTHERS * self.radius)

    def _forecast_cp(self, message: Message) -> str | None:
        p = message.period
        if not (math.isfinite(p) and p > 0) or (self.period is not None
                                                and abs(p - self.period) > 1e-9):
            return f"period {p:g} s"
        if not np.isfinite(message.values).all():
            return "points not finite"
        return self._near(message.values)

    def _measured_js(self, message: Message) -> str | None:
        q = message.values[0]
        lo = np.asarray(self.joint_lower) - self.joint_margin
        hi = np.asarray(self.joint_upper) + self.joint_margin
        if not (np.isfinite(q).all() and (q >= lo).all() and (q <= hi).all()):
            return "joint angles not finite or beyond their limits"
        return None

    def _servo_jf(self, message: Message) -> str | None:
        tau = message.values[0]
        if not (np.isfinite(tau).all() and (np.abs(tau) <= np.asarray(self.torque_max)).all()):
            return "torques not finite or beyond their limits"
        return None

    def _near(self, points: np.ndarray, radius: float | None = None) -> str | None:
        radius = self.radius if radius is None else radius
        offset = points - np.asarray(self.center)
        if not (np.abs(offset) <= radius).all() or (  # each coordinate first: no overflow
                points.size and np.max(np.linalg.norm(offset, axis=1)) > radius):
            return f"a point more than {radius * 1e3:g} mm from the registration"
        return None
