"""From predictor samples to the MPC's N control-rate reference points.

A refresh runs on each sample's arrival (the loop decides when: once per raw sample of a slow
sensor, or every ``downsample`` ticks on the newest sample of a fast one), in one call::

    refresh(tick, z, stamp):  gate → predictor.update(z) → predictor.predict(K)
                              → interpolation → guard → placement

It takes the newest measured sample ``z(t_a)``, measured at ``t_a`` (the anchor; a sensor's
latency makes it older than the current tick), and forecasts ``K`` points at the predictor's
period ``dt``::

    nodes  t_a + k·dt,  k = 0 … K      values  z(t_a), ẑ(t_a + dt), …, ẑ(t_a + K·dt)

Each control tick ``t`` until the next refresh takes its N points ``r_j = r(t + j·Ts),
j = 1 … N`` from a piecewise-cubic (4-node Lagrange) interpolation of these nodes: with
``s = (τ − t_a)/dt``, the window of nodes ``m … m+3`` around the interval of s
(``m = clip(⌊s⌋ − 1, 0, K − 3)``) and ``u = s − m``::

    r(τ) = −(u−1)(u−2)(u−3)/6·z_m + u(u−2)(u−3)/2·z_{m+1}
           − u(u−1)(u−3)/2·z_{m+2} + u(u−1)(u−2)/6·z_{m+3}

The nodes are passed through exactly, so that at each sample instant the reference is the
forecast of that sample; the cubic follows the motion's curvature between two samples of a slow
sensor closer than Tuna et al.'s quadratic, which the robot tracks with a smaller miss at the
samples (the decision record *The reference's interpolation*). Beyond the last node the last
window's cubic extrapolates (at most the last 2.5 ms of the last horizon with the paper's K = 4
and downsample 15). ``K = prediction_points +
⌈latency/dt⌉``: a sensor's latency is predicted across (Yuen et al. 2009's delay compensation).

Outlier gate (innovation gating, :mod:`rhmpc.control.gate`): while *locked*, a sample whose miss
e = z − ẑ (ẑ the forecast made for it one period earlier) has ‖e‖ > max(floor, 4·e_rms) is
treated as missing (the floor is given, or 4 × the robust RMS of the first misses on the data
themselves); e_rms² is the exponentially weighted mean of ‖e‖² over the accepted samples (weight
1/50), so a predictor with larger one-step errors gets a proportionally wider gate. Rejections
are counted in the predictor's ``counts["outliers_rejected"]``. After ``max_rejections``
consecutive rejections the gate *unlocks* and accepts every sample (a real jump, or a forecast
gone wrong: gating on a wrong forecast would run the predictor open-loop and let it diverge)
until ``relock`` consecutive samples fall inside it again (``counts["gate_unlocked"]``).

Retraction: the gate judges a sample by the forecast made from the samples before it, so an
outlier small enough to pass (a cycle slip's partly interpolated sample, 0.1–0.25 mm off) is
learnt, and the forecast made from it misses the next, good sample — which a locked gate would
then reject, and the next ones, until it unlocks. So when a sample falls outside the gate
around ẑ_{n+1|n} but inside it around ẑ_{n+1|n−1}, the two-step forecast made before the newest
accepted sample z_n, it is z_n that was off: the predictor retracts z_n (``retract``: replaced
by its forecast, as if missing; ``counts["retracted"]``) and z_{n+1} is accepted. Predictors
that cannot retract (the default) keep the plain gate.

A forecast made outside (``forecast(tick, stamp, points)``, a predictor in another process) takes
the place of the refresh's own nodes: the same interpolation and guard, then the refreshes
only keep the predictor learning until ``refresh_ticks`` ticks pass without one.

Placement: the predicted reference works in the sensor's frame (d = 1 or 3 axes), where its
samples were measured: a predictor reads in the loop what it reads open loop. After
``place(origin, center)`` its ``horizon`` returns workspace points ``r = origin + E (r_s − c)``
(N, 3), ``c`` the sensor's point placed at ``origin`` (0 for the exact reference's centred
truth), ``E`` embedding a 1-D motion along x.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rhmpc.control.gate import OutlierGate
from rhmpc.control.interpolation import WINDOW, interpolation_matrix, lagrange_weights, windows
from rhmpc.positions import ArrayTruth, embed3
from rhmpc.predictors.base import is_measured

#: The most latency the exported controller's refresh forecasts across, and the oldest a
#: forecast from outside may be when it arrives [s].
LATENCY_CAP = 0.25

__all__ = ["LATENCY_CAP", "ExactReference", "PredictedReference", "ReferenceSettings",
           "interpolation_matrix", "lagrange_weights", "windows"]


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


def _origin(origin, name: str = "origin") -> np.ndarray:
    origin = np.array(origin, dtype=float).reshape(-1)
    if origin.shape != (3,) or not np.all(np.isfinite(origin)):
        raise ValueError(f"{name} must be 3 finite coordinates [m], got {origin!r}")
    return origin


class PredictedReference:
    """The N-point reference from a predictor, refreshed on each sample's arrival.

    Parameters
    ----------
    predictor : rhmpc.predictors.Predictor
        Runs at its ``dt`` (``downsample · Ts``, or a slow sensor's sample period); fed the
        POI's samples in the sensor's frame [m] (module docstring: placement). A multi-point
        predictor (``multi_point``) also gets the other tracked points' samples of each
        refresh.
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
        self.settings = settings or ReferenceSettings()
        s = self.settings
        self.predictor = predictor
        self.Ts, self.N, self.refresh_ticks = float(Ts), int(horizon), int(refresh_ticks)
        self.dt = float(predictor.dt)
        if not self.dt <= refresh_ticks * Ts * (1 + 1e-9):
            raise ValueError(f"predictor dt {self.dt} s is longer than refresh_ticks·Ts = "
                             f"{refresh_ticks * Ts} s")
        floor = s.gate_floor
        self.gate = None if floor == 0 else OutlierGate(
            floor, s.outlier_max_rejections, self.RELOCK,
            math.ceil(s.gate_calibration / self.dt))
        self.prediction_points = s.prediction_points
        self._multi_point = bool(getattr(predictor, "multi_point", False))
        #: optional ``observe(t, heart_rate_hz)`` scorer of the predictor's heart-rate estimate,
        #: called after every forecast
        self.monitor = None
        self._span = self.refresh_ticks + self.N  # ticks a refresh covers: its period + N
        self._lead = np.arange(1, self._span + 1) * (self.Ts / self.dt)  # (τ − now)/dt
        # Interpolation matrices by (nodes, (now − t0)/Ts): with sensor stamps on the tick grid
        # only a few offsets occur, so a refresh is one small product instead of a rebuild.
        self._matrices: dict[tuple[int, float], np.ndarray] = {}
        self.origin = self.center = np.zeros(3)  # the placement (:meth:`place`)
        self.reset()

    def place(self, origin, center=(0.0, 0.0, 0.0)) -> None:
        """From now on :meth:`horizon` returns workspace points origin + E (r_s − center)
        (N, 3) [m], r_s in the sensor's frame: ``center`` [m] (d or 3 coordinates) is the
        sensor's point that sits at ``origin``, where the tool holds before the first
        sample."""
        self.origin = _origin(origin)
        self.center = _origin(embed3(np.reshape(center, (1, -1)))[0], "center")
        self._hold = np.broadcast_to(self.origin, (self.N, 3))
        if self._dense is not None:
            self._placed = self.origin - self.center + embed3(self._dense)

    def reset(self) -> None:
        """Forget the predictor, the gate and the points."""
        self.predictor.reset()
        self._dense: np.ndarray | None = None  # (span, d) points of the last refresh
        self._placed = np.broadcast_to(self.origin, (self._span, 3))  # until the first sample
        self._hold = np.broadcast_to(self.origin, (self.N, 3))
        self._first = 0  # tick of the first point
        self._anchor: float | None = None  # t_a of the newest node [s]
        self._forecast: np.ndarray | None = None  # ẑ of the next sample, made one period ago
        self._second: np.ndarray | None = None  # ẑ of the sample after it, made then too
        self._before: np.ndarray | None = None  # ẑ of the next sample made two periods ago
        self._held: np.ndarray | None = None  # the last accepted sample …
        self._held_stamp = 0.0  # … and its time [s]
        self.age_sum, self.age_count = 0.0, 0  # Σ (now − t_a) over forecasts from a sample
        self._external_stamp, self._external_until = -math.inf, 0  # forecasts from outside
        if self.gate is not None:
            self.gate.reset()

    def refresh(self, tick: int, z: np.ndarray | None, stamp: float,
                others: np.ndarray | None = None) -> None:
        """A sample's arrival on ``tick``: ``z`` measured at ``stamp`` [s] (None or NaN: none
        new), and ``others`` the other tracked points' samples of that instant (a multi-point
        predictor reads them). Gate, update, forecast, interpolation, guard, placement."""
        made = self.nodes(tick, z, stamp, others)
        if made is not None and tick >= self._external_until:  # else a forecast from outside
            self._interpolate(tick, *made, self._held, self._held_stamp, restart=True)

    def nodes(self, tick: int, z: np.ndarray | None, stamp: float,
              others: np.ndarray | None = None) -> tuple[np.ndarray, float] | None:
        """A refresh's gate, update and forecast: the nodes it interpolates, (K, d) [m] at
        ``t0 + k·dt``, and ``t0`` [s] — what a predictor in another process sends
        (:meth:`forecast`) — or None while nothing has been measured."""
        z = self._gated(z)
        if z is None and self._anchor is None:
            return None  # nothing measured yet (nor lost): keep holding
        if self._multi_point:
            self.predictor.update(z, others)
        else:
            self.predictor.update(z)
        if z is not None:
            self._anchor, self._held, self._held_stamp = stamp, np.array(z, dtype=float), stamp
        else:
            self._anchor += self.dt  # the predictor advanced one period open-loop
        latency = max(0.0, tick * self.Ts - self._anchor)
        points = self.predictor.predict(self.prediction_points
                                        + math.ceil(latency / self.dt - 1e-9))
        self._keep_forecasts(points, measured=z is not None)
        if z is None:
            return points, self._anchor + self.dt
        self.age_sum += latency
        self.age_count += 1
        return np.concatenate((np.reshape(z, (1, -1)), points)), self._anchor

    def forecast(self, tick: int, stamp: float, points: np.ndarray) -> bool:
        """A forecast made outside (a predictor in another process) arriving on ``tick``:
        ``points[k]`` the POI at ``stamp + k·dt`` in the sensor's frame [m], k = 0 … K − 1, 4 ≤ K ≤
        ``prediction_points + ⌈LATENCY_CAP/dt⌉ + 1``, ``points[0]`` the newest sample as that
        predictor took it. Interpolated and guarded as a refresh's own nodes (the guard holds
        ``points[0]``); for the next ``refresh_ticks`` ticks the refreshes only keep the
        predictor learning, then they serve again. Returns whether it was taken: points not
        finite or of another shape, or a stamp after tick + 1, count ``external_rejected``; a
        stamp older than the last taken one's or more than LATENCY_CAP before ``tick``,
        ``external_stale``."""
        nodes, counts = np.array(points, dtype=float), self.predictor.counts
        most = self.prediction_points + math.ceil(LATENCY_CAP / self.dt) + 1
        if not (math.isfinite(stamp) and stamp <= (tick + 1) * self.Ts and nodes.ndim == 2
                and WINDOW <= len(nodes) <= most and np.isfinite(nodes).all()):
            counts["external_rejected"] += 1
            return False
        if stamp < self._external_stamp or tick * self.Ts - stamp > LATENCY_CAP:
            counts["external_stale"] += 1
            return False
        counts["external"] += 1
        self._external_stamp, self._external_until = stamp, tick + self.refresh_ticks
        self._interpolate(tick, nodes, stamp, nodes[0], stamp, restart=False)
        return True

    def _gated(self, z: np.ndarray | None) -> np.ndarray | None:
        """``z`` if it is a measurement the gate accepts (retracting the previous sample where
        it was the outlier), else None."""
        if not is_measured(z):  # the predictors' test (as_sample): what is not gated is not learnt
            return None
        if self._forecast is None:
            return z
        gate, counts = self.gate, self.predictor.counts
        miss2 = gate.miss2(z, self._forecast)  # judged once, used twice
        if (self._before is not None and not gate.inside(z, self._forecast, miss2)
                and gate.inside(z, self._before) and self.predictor.retract()):
            gate.accept(z, self._before, counts)  # the previous sample was the outlier
            return z
        return z if gate.accept(z, self._forecast, counts, miss2) else None

    def _keep_forecasts(self, points: np.ndarray, measured: bool) -> None:
        """Keep the one- and two-step forecasts the gate judges the next samples by."""
        if self.gate is None:
            return
        ready = getattr(self.predictor, "ready", True)
        # the two-step forecast made before this refresh's sample, if one was accepted
        self._before = self._second if measured else None
        self._forecast = points[0] if ready else None
        self._second = points[1] if ready else None

    def _interpolate(self, tick: int, nodes: np.ndarray, t0: float, held: np.ndarray | None,
                     held_stamp: float, restart: bool) -> None:
        """The points of the ticks after ``tick`` from the nodes at ``t0 + k·dt``:
        interpolated, guarded against ``held`` (measured at ``held_stamp``), placed."""
        now = tick * self.Ts
        self._dense = self._interpolation(nodes.shape[0], now - t0) @ nodes
        self._first = tick + 1
        s = self.settings
        if s.guard_speed > 0 and held is not None:
            lead = now + self._span * self.Ts - held_stamp  # [s] to the last point
            gap = np.abs(self._dense - held)
            if gap.flat[gap.argmax()] > s.guard_margin + s.guard_speed * lead:
                self._diverged(held, restart)
        self._placed = self.origin - self.center + embed3(self._dense)
        if self.monitor is not None:
            self.monitor.observe(now, self.predictor.heart_rate_hz)

    def _interpolation(self, n_nodes: int, age: float) -> np.ndarray:
        """The matrix of :func:`interpolation_matrix` for nodes starting ``age`` s before now."""
        key = (n_nodes, round(age / self.Ts, 6))
        W = self._matrices.get(key)
        if W is None:
            if len(self._matrices) >= 64:  # off-grid stamps (jittery recordings): stay bounded
                self._matrices.clear()
            W = self._matrices[key] = interpolation_matrix(self._lead + age / self.dt, n_nodes)
        return W

    def _diverged(self, held: np.ndarray, restart: bool) -> None:
        """Hold ``held``; with ``restart``, restart the predictor from it (counts are kept)."""
        if restart:
            counts = self.predictor.counts.copy()
            self.predictor.reset()
            self.predictor.counts.update(counts)
            self.predictor.update(held)
            self._forecast = self._second = self._before = None
        self.predictor.counts["reference_guard"] += 1
        self._dense = np.broadcast_to(held, self._dense.shape)

    @property
    def locked(self) -> bool:
        """True while the outlier gate rejects samples outside it (False without a gate)."""
        return self.gate is not None and self.gate.locked

    @property
    def mean_age(self) -> float:
        """Mean age of the newest sample when a forecast is made from it [s] (NaN if none)."""
        return self.age_sum / self.age_count if self.age_count else math.nan

    def horizon(self, tick: int) -> np.ndarray:
        """r_{tick+1} … r_{tick+N} in the workspace (N, 3) [m]: the points of the last refresh
        (a skipped refresh holds its last N), or the origin before the first sample. A read-only
        view of an array that the next refresh replaces."""
        if self._dense is None:
            return self._hold
        start = min(max(tick + 1 - self._first, 0), self._span - self.N)
        return self._placed[start : start + self.N]


class ExactReference:
    """"Exact reference information" (Tuna et al.): the true future, no predictor.

    ``truth`` is the centred POI position at every tick of the run plus a horizon's margin: an
    array (n, d), or a truth read in windows (``window(i0, i1)``, ``n_ticks``, ``dim``), which
    keeps memory flat in run length. Gaps in it (NaN: dropouts of a recorded stream used as the
    truth) are bridged linearly between the finite ticks around them (constant before the first
    and after the last), so that the MPC is never handed NaN; the metrics still skip those
    ticks. Read in windows of ``window`` ticks, forward in time (reading backwards restarts from
    tick 0), the points are those of the whole array.
    """

    predictor = None

    def __init__(self, truth, horizon: int, window: int = 8192) -> None:
        self._truth = truth if hasattr(truth, "window") else ArrayTruth(truth)
        self.N, self._size = horizon, int(window)
        self._origin = np.zeros(3)
        self._restart()

    def _restart(self) -> None:
        self._w0 = 0  # tick of self._points[0]
        self._points = np.empty((0, 3))
        self._last: list[tuple[int, float] | None] = [None] * self._truth.dim  # finite, before

    def _bridged(self, a: int, b: int) -> np.ndarray:
        """Truth of ticks a … b − 1 with its gaps bridged (windows are read in order)."""
        truth, n = self._truth, self._truth.n_ticks
        raw = np.array(truth.window(a, b), dtype=float)
        ticks = np.arange(a, b)
        for axis in range(raw.shape[1]):
            column = raw[:, axis]
            good = np.isfinite(column)
            previous = self._last[axis]
            if good.any():
                k = np.flatnonzero(good)[-1]
                self._last[axis] = (a + int(k), float(column[k]))
            if good.all():
                continue
            xs, fs = list(ticks[good]), list(column[good])
            if previous is not None:
                xs.insert(0, previous[0])
                fs.insert(0, previous[1])
            c = b
            while not good[-1] and c < n:  # the gap runs past the window: find its end
                ahead = np.asarray(truth.window(c, min(c + self._size, n)))[:, axis]
                found = np.flatnonzero(np.isfinite(ahead))
                if found.size:
                    xs.append(c + int(found[0]))
                    fs.append(float(ahead[found[0]]))
                    break
                c += self._size
            if not xs:
                raise ValueError("the exact reference has no finite sample on some axis")
            column[~good] = np.interp(ticks[~good], xs, fs)
        return raw

    def _cover(self, start: int, stop: int) -> np.ndarray:
        """Points of ticks start … stop − 1 (fewer at the end of the truth)."""
        if start < self._w0:
            self._restart()
        stop = min(stop, self._truth.n_ticks)
        end = self._w0 + self._points.shape[0]
        if stop > end:
            parts = [self._points[start - self._w0 :]] if start < end else []
            if start > end:  # skipped ahead: read (and drop) the ticks in between, in order
                while end < start:
                    self._bridged(end, min(end + self._size, start))
                    end = min(end + self._size, start)
            self._w0 = min(start, end)
            while end < stop:
                b = min(end + self._size, self._truth.n_ticks)
                parts.append(self._origin + embed3(self._bridged(end, b)))
                end = b
            self._points = np.concatenate(parts)
        return self._points

    def place(self, origin, center=(0.0, 0.0, 0.0)) -> None:
        """From now on :meth:`horizon` returns workspace points origin + E r_c (N, 3) [m], r_c
        the centred truth (``center``, the sensor's registration, is not read: no sample is)."""
        self._origin = _origin(origin)
        self._restart()

    def reset(self) -> None:
        pass

    def refresh(self, tick: int, z: np.ndarray | None, stamp: float,
                others: np.ndarray | None = None) -> None:
        pass

    def horizon(self, tick: int) -> np.ndarray:
        """r_{tick+1} … r_{tick+N} in the workspace (N, 3) [m]."""
        return self.horizons(tick, 1)[0]

    def horizons(self, tick: int, count: int) -> np.ndarray:
        """:meth:`horizon` of ticks tick … tick + count − 1 as one read-only (count, N, 3)
        array (:func:`windows`; a view of an array never changed)."""
        points = self._cover(tick + 1, tick + count + self.N)
        return windows(points, tick + 1 - self._w0, count, self.N)
