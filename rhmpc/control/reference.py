"""From a predictor's samples to the MPC's N control-rate reference points.

The reference's per-tick work runs in the controller's library (``rhmpc_reference.c``, the C
that ``rhmpc export`` writes: :class:`rhmpc.control.controller.Controller`); this module keeps
its settings and drives it with a predictor of :mod:`rhmpc.predictors`. A refresh runs on each
sample's arrival (the loop decides when: once per raw sample of a slow sensor, or every
``downsample`` ticks on the newest sample of a fast one)::

    refresh(tick, z, stamp):  gate → predictor.update(z) → predictor.predict(K)
                              → interpolation → guard → placement

The newest measured sample ``z(t_a)``, measured at ``t_a`` (the anchor; a sensor's latency
makes it older than the current tick), and ``K`` forecast points at the predictor's period
``dt`` are the nodes::

    nodes  t_a + k·dt,  k = 0 … K      values  z(t_a), ẑ(t_a + dt), …, ẑ(t_a + K·dt)

``K = prediction_points + ⌈latency/dt⌉`` (at most ``⌈LATENCY_CAP/dt⌉`` more): a sensor's latency
is predicted across (Yuen et al. 2009's delay compensation). Each control tick ``t`` until the
next refresh takes its N points ``r_j = r(t + j·Ts)`` from a piecewise-cubic (4-node Lagrange)
interpolation of the nodes: with ``s = (τ − t_a)/dt``, the window of nodes ``m … m+3``
(``m = clip(⌊s⌋ − 1, 0, K − 3)``) and ``u = s − m``::

    r(τ) = −(u−1)(u−2)(u−3)/6·z_m + u(u−2)(u−3)/2·z_{m+1}
           − u(u−1)(u−3)/2·z_{m+2} + u(u−1)(u−2)/6·z_{m+3}

The nodes are passed through exactly (the decision record *The reference's interpolation*).

Outlier gate (innovation gating): while *locked*, a sample whose miss e = z − ẑ (ẑ the forecast
made for it one period earlier) has ‖e‖ > max(floor, 4·e_rms) is treated as missing (the floor
is given, or 4 × the robust RMS of the first misses on the data themselves); e_rms² is the
exponentially weighted mean of ‖e‖² over the accepted samples (weight 1/50). Rejections count
as ``counts["outliers_rejected"]``. After ``max_rejections`` consecutive rejections the gate
*unlocks* and accepts every sample until ``relock`` consecutive samples fall inside it again
(``counts["gate_unlocked"]``). Retraction: a sample outside the gate around ẑ_{n+1|n} but
inside it around ẑ_{n+1|n−1}, the two-step forecast made before the newest accepted sample
z_n, shows that z_n was the outlier: the predictor retracts z_n (``retract``, replaced by its
forecast, ``counts["retracted"]``) and z_{n+1} is accepted.

Reference guard: forecasts farther from the last accepted sample than ``guard_margin +
guard_speed · lead`` mean a diverged predictor: the reference holds that sample and the
predictor restarts from it (``counts["reference_guard"]``).

A forecast made outside (``forecast(tick, stamp, points)``, a predictor in another process)
takes the place of the refresh's own nodes for ``refresh_ticks`` ticks. Placement: the
reference works in the sensor's frame (d = 1 or 3 axes); after ``place(origin, center)`` its
points are ``r = origin + E (r_s − c)``, ``c`` the sensor's point placed at ``origin``, ``E``
embedding a 1-D motion along x.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rhmpc.positions import embed3, place_point

#: The most latency a refresh forecasts across, and the oldest a forecast from outside may be
#: when it arrives [s].
LATENCY_CAP = 0.25
#: The events the library counts for the reference (the rest are the predictor's own).
LIBRARY_COUNTS = ("outliers_rejected", "gate_unlocked", "reference_guard", "forecast_capped",
                  "external", "external_rejected", "external_stale")

#: Nodes of the interpolation's window (cubic: 4).
WINDOW = 4

__all__ = ["LATENCY_CAP", "GateRule", "PredictedReference", "ReferenceSettings"]


@dataclass(frozen=True)
class ReferenceSettings:
    """How a predictor's samples become the MPC's reference (the ``[reference]`` table).

    Attributes
    ----------
    prediction_points : int
        Points the predictor forecasts per refresh, before latency compensation (4: Tuna et
        al. 2013 §VIII-B, M = 4 at 7.5 ms covers the 25-ms horizon); at least 4, the cubic's
        window.
    outlier_gate : float or str
        A sensor sample farther from its one-step forecast than max(floor, 4 × the running RMS
        forecast miss) is treated as missing (echo outliers: the heart cannot jump millimetres
        between two samples). ``"auto"`` (default): the floor is 4 × the RMS one-step miss of
        the predictor on the data themselves, measured over ``gate_calibration`` seconds after
        as many seconds of convergence (misses beyond 5 × their median left out, so that an
        outlier in that window does not widen the gate); every sample is accepted until then.
        A number: that floor [m]; 0 disables the gate. The choice is recorded in the design
        decisions (outlier gate).
    gate_calibration : float
        Length of the ``"auto"`` gate's convergence and of its calibration, each, in the
        predictor's own forecasts [s] (5 s: several beats).
    outlier_max_rejections : int
        After this many consecutive rejected samples the gate opens (a real jump, or a forecast
        gone wrong) until 20 samples in a row fall inside it again [samples]. Default 3: a
        sonomicrometer's cycle slip lasts up to 8 ms and the causal playback adds one raw period
        (3.9 ms at 257 Hz), so it reaches ``⌈11.9 / 7.5⌉ + 1 = 3`` samples of the predictor.
    guard_speed : float
        Reference guard: forecasts farther from the last accepted sample than ``guard_margin +
        guard_speed · lead`` mean a diverged predictor; the reference then holds that sample and
        the predictor restarts. Above the fastest POI motion of the replicas (0.21 m/s); 0
        disables [m/s].
    guard_margin : float
        Constant part of the guard's reach [m].
    """

    prediction_points: int = 4
    outlier_gate: float | str = "auto"
    gate_calibration: float = 5.0
    outlier_max_rejections: int = 3
    guard_speed: float = 0.3
    guard_margin: float = 2e-3

    def __post_init__(self) -> None:
        for name, least in (("prediction_points", WINDOW), ("outlier_max_rejections", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < least:
                raise ValueError(f"{name} must be an integer >= {least}, got {value!r}")
        gate = self.outlier_gate
        if gate != "auto" and not (isinstance(gate, int | float) and not isinstance(gate, bool)
                                   and math.isfinite(gate) and gate >= 0):
            raise ValueError(f"outlier_gate must be 'auto' or a number >= 0 [m], got {gate!r}")
        for name, positive in (("gate_calibration", True), ("guard_speed", False),
                               ("guard_margin", True)):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value)
                    and (value > 0 if positive else value >= 0)):
                raise ValueError(f"{name} must be a finite number {'>' if positive else '>='} "
                                 f"0, got {value!r}")

    @property
    def gate_floor(self) -> float | None:
        """The outlier gate's fixed floor [m] (0: no gate), or None for one from the data."""
        return None if self.outlier_gate == "auto" else float(self.outlier_gate)


def _three(z) -> np.ndarray:
    """A sample as 3 coordinates (d < 3: the missing axes zero)."""
    z = np.asarray(z, dtype=float)
    return z if z.shape == (3,) else embed3(z.reshape(1, -1))[0]


@dataclass(frozen=True)
class GateRule:
    """The outlier gate's numbers, as the library runs them (module docstring).

    Attributes
    ----------
    floor : float or None
        The smallest gate radius [m]; None: calibrated on the data, 4 × the RMS of the misses
        over the second ``calibration`` samples no larger than 5 × their median.
    max_rejections : int
        Consecutive rejections after which the gate unlocks [samples].
    relock : int
        Consecutive samples inside the gate after which it locks again [samples].
    calibration : int
        Samples of convergence, then of calibration, each (floor None) [samples].
    """

    floor: float | None
    max_rejections: int
    relock: int
    calibration: int
    #: The smallest calibrated floor [m] (a noise-free signal would give 0).
    MIN_FLOOR = 1e-6


class PredictedReference:
    """The N-point reference from a predictor, refreshed on each sample's arrival, bound to a
    controller's library (module docstring).

    Parameters
    ----------
    predictor : rhmpc.predictors.Predictor
        Runs at its ``dt`` (``downsample · Ts``, or a slow sensor's sample period); fed the
        POI's samples in the sensor's frame [m]. A multi-point predictor (``multi_point``)
        also gets the other tracked points' samples of each refresh.
    Ts : float
        Control period [s].
    horizon : int
        N, reference points per tick.
    refresh_ticks : int
        The most ticks one refresh must cover until the next (``downsample``, or a slow
        sensor's period with a margin); at least ``dt / Ts``.
    settings : ReferenceSettings, optional
        Forecast points, outlier gate and guard (default: :class:`ReferenceSettings`).
    """

    #: Consecutive samples inside the gate after which an unlocked gate locks again.
    RELOCK = 20

    def __init__(self, predictor, Ts: float, horizon: int, refresh_ticks: int,
                 settings: ReferenceSettings | None = None) -> None:
        self.settings = s = settings or ReferenceSettings()
        self.predictor = predictor
        self.Ts, self.N, self.refresh_ticks = float(Ts), int(horizon), int(refresh_ticks)
        self.dt = float(predictor.dt)
        if not self.dt <= refresh_ticks * Ts * (1 + 1e-9):
            raise ValueError(f"predictor dt {self.dt} s is longer than refresh_ticks·Ts = "
                             f"{refresh_ticks * Ts} s")
        floor = s.gate_floor
        self.gate = None if floor == 0 else GateRule(
            floor, s.outlier_max_rejections, self.RELOCK, math.ceil(s.gate_calibration / self.dt))
        self.prediction_points = s.prediction_points
        self.span = self.refresh_ticks + self.N  # ticks a refresh covers: its period + N
        self._multi_point = bool(getattr(predictor, "multi_point", False))
        #: optional ``observe(t, heart_rate_hz)`` scorer of the predictor's heart-rate estimate,
        #: called after every forecast
        self.monitor = None
        self.origin = self.center = np.zeros(3)
        self._controller = None
        self._held: np.ndarray | None = None  # the last accepted sample

    def bind(self, controller) -> None:
        """Run in ``controller``'s library (:class:`rhmpc.control.controller.Controller`)."""
        from rhmpc.control.export.layout import COUNTS, RETRACT

        self._controller, lib = controller, controller._lib
        self._calls = lib.rhmpc_sample, lib.rhmpc_nodes, lib.rhmpc_interpolate
        self._retract = RETRACT(lambda _: int(bool(self.predictor.retract())))
        self._accepted, self._t0 = np.zeros(1, dtype=np.intc), np.zeros(1)
        self._at = self._accepted.ctypes.data, self._t0.ctypes.data
        most = self.prediction_points + math.ceil(LATENCY_CAP / self.dt) + 1
        self._node_view = np.ctypeslib.as_array(lib.rhmpc_node_values(controller._addr),
                                                (most, 3))
        self._index = np.array([COUNTS.index(name) for name in LIBRARY_COUNTS])

    def place(self, origin, center=(0.0, 0.0, 0.0)) -> None:
        """From now on the points are workspace points origin + E (r_s − center) (N, 3) [m],
        r_s in the sensor's frame: ``center`` [m] (d or 3 coordinates) is the sensor's point that
        sits at ``origin``, where the tool holds before the first sample."""
        self.origin = place_point(origin)
        self.center = place_point(embed3(np.reshape(center, (1, -1)))[0], "center")
        if self._controller is not None:
            self._controller.place(self.origin, self.center)

    def reset(self) -> None:
        """Forget the predictor (the library's reference starts again with ``rhmpc_init``)."""
        self.predictor.reset()
        self._held = None

    def refresh(self, tick: int, z: np.ndarray | None, stamp: float,
                others: np.ndarray | None = None) -> None:
        """A sample's arrival on ``tick``: ``z`` measured at ``stamp`` [s] (None or NaN: none
        new), and ``others`` the other tracked points' samples of that instant. Gate, update,
        forecast, interpolation, guard, placement."""
        if not self._made(tick, z, stamp, others):
            return
        verdict = self._calls[2](self._controller._addr, tick)
        if verdict == 1:
            self._restart()
            self._count()
        if verdict >= 0 and self.monitor is not None:
            self.monitor.observe(tick * self.Ts, self.predictor.heart_rate_hz)

    def nodes(self, tick: int, z: np.ndarray | None, stamp: float,
              others: np.ndarray | None = None) -> tuple[np.ndarray, float] | None:
        """A refresh's gate, update and forecast: the nodes it interpolates, (K, 3) [m] at
        ``t0 + k·dt``, and ``t0`` [s] — what a predictor in another process sends
        (:meth:`forecast`) — or None while nothing has been measured."""
        n = self._made(tick, z, stamp, others)
        return None if not n else (self._node_view[:n].copy(), float(self._t0[0]))

    def _made(self, tick: int, z, stamp: float, others) -> int:
        """The gate on ``z``, the predictor's update and forecast, the library's nodes: their
        count (0 while nothing has been measured)."""
        c = self._controller
        sample, make_nodes, _ = self._calls
        K = sample(c._addr, tick, stamp, c._sample(None if z is None else _three(z)),
                   self._retract, None, self._at[0])
        if K < 0:
            raise ValueError(f"the stamp {stamp!r} is not a finite time")
        if K == 0:
            return 0  # nothing measured yet (nor lost): keep holding
        x = None
        if self._accepted[0]:
            x = self._held = np.array(z, dtype=float)
        if self._multi_point:
            self.predictor.update(x, others)
        else:
            self.predictor.update(x)
        points = self.predictor.predict(K)
        if points.shape[1] != 3 or not points.flags.c_contiguous:
            points = np.ascontiguousarray(embed3(points), dtype=float)
        n = make_nodes(c._addr, points.ctypes.data, K, self._ready(), self._at[1])
        self._count()
        return n

    def _ready(self) -> bool:
        """Whether the predictor's forecasts are its own (not the hold of its newest sample)."""
        return bool(getattr(self.predictor, "ready", True))

    def forecast(self, tick: int, stamp: float, points: np.ndarray) -> bool:
        """A forecast made outside (a predictor in another process) arriving on ``tick``:
        ``points[k]`` the POI at ``stamp + k·dt`` in the sensor's frame [m], k = 0 … K − 1, 4 ≤ K ≤
        ``prediction_points + ⌈LATENCY_CAP/dt⌉ + 1``, ``points[0]`` the newest sample as that
        predictor took it (``rhmpc_forecast``). Returns whether it was taken."""
        taken = self._controller.take_forecast(tick, stamp,
                                               embed3(np.asarray(points, dtype=float)))
        self._count()
        if taken and self.monitor is not None:
            self.monitor.observe(tick * self.Ts, self.predictor.heart_rate_hz)
        return taken

    def _count(self) -> None:
        """The library's counts of the reference's events, into the predictor's ``counts``."""
        values = self._controller.counts_view[self._index]
        if values.any():
            counts = self.predictor.counts
            for name, value in zip(LIBRARY_COUNTS, values.tolist(), strict=True):
                if value:
                    counts[name] = value

    def _restart(self) -> None:
        """Restart the predictor from the last accepted sample (its counts are kept)."""
        counts = self.predictor.counts.copy()
        self.predictor.reset()
        self.predictor.counts.update(counts)
        self.predictor.update(self._held)

    @property
    def locked(self) -> bool:
        """True while the outlier gate rejects samples outside it (False without a gate)."""
        return self.gate is not None and bool(self._controller._pub.gate_locked)

    @property
    def mean_age(self) -> float:
        """Mean age of the newest sample when a forecast is made from it [s] (NaN if none)."""
        return self._controller.mean_age

    def horizon(self, tick: int) -> np.ndarray:
        """r_{tick+1} … r_{tick+N} in the workspace (N, 3) [m] (a read-only view)."""
        return self._controller.horizon(tick)
