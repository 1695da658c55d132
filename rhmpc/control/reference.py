"""From predictor samples to the MPC's N control-rate reference points.

The predictor runs with period ``dt``: every ``downsample`` ticks on the newest sample delivered
to the control rate (``dt = downsample·Ts``, 7.5 ms in the paper), or once per raw sample of a
slower sensor (``dt`` its sample period, :mod:`sim.loop.clock`). Each refresh takes the newest
measured sample ``z(t_a)``, measured at ``t_a`` (the anchor; a sensor's latency makes it older
than the current tick), and forecasts ``K`` points::

    nodes  t_a + k·dt,  k = 0 … K      values  z(t_a), ẑ(t_a + dt), …, ẑ(t_a + K·dt)

Each control tick ``t`` between two predictor updates takes its N points
``r_j = r(t + j·Ts), j = 1 … N`` from a piecewise-quadratic (3-node Lagrange) interpolation of
these nodes: with ``s = (τ − t_a)/dt`` and the window of nodes ``m, m+1, m+2``
(``m = min(⌊s⌋, K − 2)``), ``u = s − m``::

    r(τ) = ½(u−1)(u−2)·z_m − u(u−2)·z_{m+1} + ½u(u−1)·z_{m+2}

Beyond the last node the last window's quadratic extrapolates (with the paper's K = 4 and
downsample 15 that is at most the last 2.5 ms of the last horizon before the next update).
``K = prediction_points + ⌈latency/dt⌉`` so that a sensor's latency is predicted across (Yuen et
al. 2009's delay compensation).

Outlier gate (innovation gating): while *locked*, a sample whose miss e = z − ẑ (ẑ the
forecast made for it one period earlier) has ‖e‖ > max(floor, 4·e_rms) is treated as missing
(the floor is given, or 4 × the robust RMS of the first misses on the data themselves);
e_rms² is the exponentially weighted mean of ‖e‖² over the accepted samples (weight 1/50), so
a predictor with larger one-step errors gets a proportionally wider gate. Rejections
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

Placement: both references work in centred heart coordinates (d = 1 or 3 axes); after
``place(origin)`` their ``horizon`` returns workspace points ``r = origin + E r_c`` (N, 3), with
``E`` embedding a 1-D motion along x. The closed loop places once, so the offset is added once
per refresh instead of once per tick.
"""

from __future__ import annotations

import math

import numpy as np

from predictors.base import is_measured
from rhmpc.control.gate import OutlierGate
from sim.loop import embed3

#: The three Lagrange weights on nodes m, m+1, m+2 as polynomials in u = s − m, in the basis
#: (u², u, 1): ½(u−1)(u−2), −u(u−2), ½u(u−1).
_LAGRANGE = np.array([[0.5, -1.5, 1.0], [-1.0, 2.0, 0.0], [0.5, -0.5, 0.0]])


def _window_weights(s: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """``m`` (n,) and the weights as rows, shape (3, n)."""
    if n_nodes < 3:
        raise ValueError(f"quadratic interpolation needs at least 3 nodes, got {n_nodes}")
    m = np.floor(s)
    np.minimum(m, float(n_nodes - 3), out=m)
    np.maximum(m, 0.0, out=m)
    basis = np.ones((3, s.shape[0]))
    u = np.subtract(s, m, out=basis[1])
    np.multiply(u, u, out=basis[0])
    return m.astype(np.intp), _LAGRANGE @ basis


def quadratic_weights(s: np.ndarray, n_nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Window start ``m`` and the three Lagrange weights for node coordinates ``s`` (in periods).

    Returns ``m`` (n,) and ``w`` (n, 3) with r(s) = Σ_j w[:, j] · node[m + j].
    """
    m, w = _window_weights(s, n_nodes)
    return m, w.T


def interpolation_matrix(s: np.ndarray, n_nodes: int) -> np.ndarray:
    """W (n, n_nodes) with W @ nodes = the piecewise-quadratic interpolation at ``s``."""
    m, w = _window_weights(s, n_nodes)
    n = s.shape[0]
    W = np.zeros(n * n_nodes)
    m += np.arange(0, n * n_nodes, n_nodes)  # flat index of each row's first node
    W[m] = w[0]
    m += 1
    W[m] = w[1]
    m += 1
    W[m] = w[2]
    return W.reshape(n, n_nodes)


def windows(points: np.ndarray, first: int, count: int, N: int) -> np.ndarray:
    """Rows ``first + k … first + k + N − 1`` of ``points`` (n, d) for k < count, as one
    read-only (count, N, d) array: a view of overlapping windows, or a copy when it runs past
    the last row (the last window is then repeated: a skipped refresh holds its points).
    ``points`` must hold at least N rows."""
    last = points.shape[0] - N
    if last < 0:
        raise ValueError(f"{points.shape[0]} points cannot make windows of {N}")
    if first + count - 1 > last or not points.flags.c_contiguous:
        starts = np.minimum(np.arange(first, first + count), last)
        out = points[starts[:, None] + np.arange(N)]
    else:
        row = points.strides[0]
        out = np.ndarray((count, N, points.shape[1]), points.dtype, points, first * row,
                         (row, row, points.strides[1]))
    out.flags.writeable = False
    return out


def _origin(origin) -> np.ndarray:
    origin = np.array(origin, dtype=float).reshape(-1)
    if origin.shape != (3,) or not np.all(np.isfinite(origin)):
        raise ValueError(f"origin must be 3 finite coordinates [m], got {origin!r}")
    return origin


class PredictedReference:
    """The N-point reference from a predictor, refreshed once per predictor period.

    Parameters
    ----------
    predictor : predictors.Predictor
        Runs at its ``dt`` (``downsample · Ts``, or a slow sensor's sample period); fed centred
        heart coordinates [m].
    Ts : float
        Control period [s].
    horizon : int
        N, reference points per tick.
    refresh_ticks : int
        The most ticks one refresh must cover until the next (``downsample``, or a slow
        sensor's period with a margin); at least ``dt / Ts``.
    prediction_points : int
        Forecast points per update before latency compensation (4 in Tuna et al.).
    outlier_gate : float or None
        Floor of the :class:`OutlierGate` [m]; 0 disables the gate; None calibrates the floor
        on the first ``gate_calibration`` misses.
    max_rejections, relock, gate_calibration : int
        See :class:`OutlierGate`.
    guard_speed, guard_margin : float
        Reference guard: a forecast point farther from the last accepted sample than
        ``guard_margin + guard_speed · (its time − that sample's time)`` [m/s, m] means the
        predictor has diverged: the reference holds that sample and the predictor is reset (it
        relearns; until it is ready it holds too). ``guard_speed`` 0 disables the guard.
    """

    def __init__(
        self, predictor, Ts: float, horizon: int, refresh_ticks: int, prediction_points: int = 4,
        *, outlier_gate: float | None = 0.0, max_rejections: int = 2, relock: int = 20,
        gate_calibration: int = 100, guard_speed: float = 0.0, guard_margin: float = 2e-3,
    ) -> None:
        if prediction_points < 2:
            raise ValueError(f"prediction_points must be >= 2, got {prediction_points}")
        self.gate = None if outlier_gate == 0 else OutlierGate(
            outlier_gate, max_rejections, relock, gate_calibration)
        if not (guard_speed >= 0 and guard_margin > 0):
            raise ValueError("guard_speed must be >= 0 [m/s] and guard_margin > 0 [m]")
        self.guard_speed, self.guard_margin = guard_speed, guard_margin
        self.predictor = predictor
        self.Ts, self.N, self.refresh_ticks = Ts, horizon, refresh_ticks
        self.dt = float(predictor.dt)
        if not self.dt <= refresh_ticks * Ts * (1 + 1e-9):
            raise ValueError(f"predictor dt {self.dt} s is longer than refresh_ticks·Ts = "
                             f"{refresh_ticks * Ts} s")
        self.prediction_points = prediction_points
        #: optional ``observe(t, heart_rate_hz)`` scorer of the predictor's heart-rate estimate
        #: (:class:`sim.loop.metrics.HeartRateScore`), called after every forecast
        self.monitor = None
        # ticks a refresh covers: its period, plus the two ticks a pipelined loop runs between
        # an update and its interpolation, while it reads the previous refresh's points
        self._span = refresh_ticks + horizon + 2
        self._lead = np.arange(1, self._span + 1) * (Ts / self.dt)  # (τ − now)/dt per point
        # Interpolation matrices by (nodes, (now − t0)/Ts): with sensor stamps on the tick grid
        # only a few offsets occur, so a refresh is one small product instead of a rebuild.
        self._matrices: dict[tuple[int, float], np.ndarray] = {}
        self._origin: np.ndarray | None = None
        self.reset()

    def place(self, origin) -> None:
        """From now on ``horizon`` returns workspace points origin + E r_c, shape (N, 3) [m]."""
        self._origin = _origin(origin)
        self._placed = None if self._dense is None else self._origin + embed3(self._dense)

    def reset(self) -> None:
        self.predictor.reset()
        self._dense: np.ndarray | None = None
        self._placed: np.ndarray | None = None
        self._first = 0
        self._pending: tuple | None = None  # (tick, accepted z or None): updated, not predicted
        self._points: tuple | None = None  # (tick, z, points, latency): predicted, not placed
        self._anchor: float | None = None
        self._forecast: np.ndarray | None = None  # ẑ of the next sample, made one period ago
        self._second: np.ndarray | None = None  # ẑ of the sample after it, made then too
        self._before: np.ndarray | None = None  # ẑ of the next sample made two periods ago
        self._held: np.ndarray | None = None  # the last accepted sample …
        self._held_stamp = 0.0  # … and its time [s]
        self.age_sum, self.age_count = 0.0, 0  # Σ (now − t_a) over forecasts from a sample
        if self.gate is not None:
            self.gate.reset()

    def refresh(self, tick: int, z: np.ndarray | None, stamp: float) -> None:
        """Feed the newest sample ``z`` measured at ``stamp`` [s] (None = no new sample).

        :meth:`update` then :meth:`forecast`, the two halves a pipelined loop runs on
        consecutive ticks.
        """
        self.update(tick, z, stamp)
        self.forecast()

    def update(self, tick: int, z: np.ndarray | None, stamp: float) -> None:
        """First half of a refresh: the outlier gate and the predictor's update with ``z``."""
        valid = is_measured(z)  # the predictors' test (as_sample): what is not gated is not learnt
        if valid and self._forecast is not None:
            gate, counts = self.gate, self.predictor.counts
            miss2 = gate.miss2(z, self._forecast)  # judged once, used twice
            if (self._before is not None and not gate.inside(z, self._forecast, miss2)
                    and gate.inside(z, self._before) and self.predictor.retract()):
                gate.accept(z, self._before, counts)  # the previous sample was the outlier
            elif not gate.accept(z, self._forecast, counts, miss2):
                z, valid = None, False
        self.predictor.update(z)
        self._pending = self._points = None
        if valid:
            self._anchor, self._held, self._held_stamp = stamp, np.array(z, dtype=float), stamp
        elif self._anchor is None:
            return  # nothing measured yet: keep holding
        else:
            self._anchor += self.dt  # the predictor advanced one period open-loop
        self._pending = (tick, z if valid else None)

    def forecast(self) -> None:
        """Forecast, interpolate and guard the points of the last :meth:`update`:
        :meth:`predict` then :meth:`interpolate`, the slices a pipelined loop runs on
        consecutive ticks.

        The points are those of the update's tick; until this runs, :meth:`horizons` reads the
        previous refresh's points.
        """
        self.predict()
        self.interpolate()

    def learn(self) -> None:
        """The predictor's learning from the last :meth:`update`, where it defers it
        (:meth:`predictors.base.Predictor.learn`); otherwise it ran in the update."""
        learn = getattr(self.predictor, "learn", None)
        if learn is not None:
            learn()

    def score(self) -> None:
        """The predictor's forecast-error bookkeeping (:meth:`predictors.base.Predictor.score`),
        which a pipelined loop runs on the tick after the interpolation."""
        score = getattr(self.predictor, "score", None)
        if score is not None:
            score()

    def predict(self) -> None:
        """The predictor's forecast from the last :meth:`update`, ``K = prediction_points +
        ⌈latency/dt⌉`` points (the gate keeps the one- and two-step ones)."""
        if self._pending is None:
            return
        (tick, z), self._pending = self._pending, None
        latency = max(0.0, tick * self.Ts - self._anchor)
        points = self.predictor.predict(self.prediction_points
                                        + math.ceil(latency / self.dt - 1e-9))
        if self.gate is not None:
            ready = getattr(self.predictor, "ready", True)
            # the two-step forecast made before this refresh's sample, if one was accepted
            self._before = self._second if z is not None else None
            self._forecast = points[0] if ready else None
            self._second = points[1] if ready else None
        self._points = (tick, z, points, latency)

    def interpolate(self) -> None:
        """The N-point references of the last :meth:`predict`: interpolated, guarded, placed."""
        if self._points is None:
            return
        (tick, z, points, latency), self._points = self._points, None
        now = tick * self.Ts
        if z is not None:
            nodes = np.concatenate((np.reshape(z, (1, -1)), points))
            t0 = self._anchor
            self.age_sum += latency
            self.age_count += 1
        else:
            nodes, t0 = points, self._anchor + self.dt
        self._dense = self._interpolation(nodes.shape[0], now - t0) @ nodes
        self._first = tick + 1
        if self.guard_speed > 0 and self._held is not None:
            lead = now + self._span * self.Ts - self._held_stamp  # [s] to the last point
            gap = np.subtract(self._dense, self._held)
            np.abs(gap, out=gap)
            if gap.flat[gap.argmax()] > self.guard_margin + self.guard_speed * lead:
                self._diverged()
        if self._origin is not None:
            self._placed = self._origin + embed3(self._dense)
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

    def _diverged(self) -> None:
        """Hold the last accepted sample; restart the predictor from it (counts are kept)."""
        counts = self.predictor.counts.copy()
        self.predictor.reset()
        self.predictor.counts.update(counts)
        self.predictor.counts["reference_guard"] += 1
        self.predictor.update(self._held)
        self._forecast = self._second = self._before = None
        self._dense = np.broadcast_to(self._held, self._dense.shape)

    @property
    def locked(self) -> bool:
        """True while the outlier gate rejects samples outside it (False without a gate)."""
        return self.gate is not None and self.gate.locked

    @property
    def mean_age(self) -> float:
        """Mean age of the newest sample when a forecast is made from it [s] (NaN if none)."""
        return self.age_sum / self.age_count if self.age_count else math.nan

    def horizon(self, tick: int) -> np.ndarray | None:
        """r_{tick+1} … r_{tick+N}, or None before the first valid sample.

        Shape (N, d) in centred coordinates, or (N, 3) in the workspace after :meth:`place`.
        A view of an array that the next ``refresh`` replaces (it is never changed in place).
        """
        points = self.horizons(tick, 1)
        return None if points is None else points[0]

    def horizons(self, tick: int, count: int) -> np.ndarray | None:
        """:meth:`horizon` of ticks tick … tick + count − 1 from the current refresh, as one
        read-only (count, N, d) array (:func:`windows`), or None before the first valid
        sample."""
        dense = self._dense if self._origin is None else self._placed
        if dense is None:
            return None
        return windows(dense, tick + 1 - self._first, count, self.N)


class ExactReference:
    """"Exact reference information" (Tuna et al.): the true future, no predictor.

    ``truth`` is the centred POI position at every tick of the run plus a horizon's margin: an
    array (n, d), or a truth read in windows (``window(i0, i1)``, ``n_ticks``:
    :class:`sim.loop.streams.SourceTruth`), which keeps memory flat in run length. Gaps in it (NaN:
    dropouts of a recorded stream used as the truth) are bridged linearly between the finite
    ticks around them (constant before the first and after the last), so that the MPC is never
    handed NaN; the metrics still skip those ticks. Read in windows of ``window`` ticks, forward
    in time (reading backwards restarts from tick 0), the points are those of the whole array.
    """

    def __init__(self, truth, horizon: int, window: int = 8192) -> None:
        if not hasattr(truth, "window"):
            from sim.loop.streams import ArrayTruth

            array = np.array(truth, dtype=float)
            if not np.all(np.isfinite(array).any(axis=0)):
                raise ValueError("the exact reference has no finite sample on some axis")
            truth = ArrayTruth(array, np.zeros(array.shape[1]))
        self._truth, self.N, self._size = truth, horizon, int(window)
        self._origin: np.ndarray | None = None
        self._restart()

    def _restart(self) -> None:
        self._w0 = 0  # tick of self._points[0]
        self._points = np.empty((0, 3 if self._origin is not None else self._truth.dim))
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
                new = self._bridged(end, b)
                parts.append(new if self._origin is None else self._origin + embed3(new))
                end = b
            self._points = np.concatenate(parts)
        return self._points

    def place(self, origin) -> None:
        """From now on ``horizon`` returns workspace points origin + E r_c, shape (N, 3) [m]."""
        self._origin = _origin(origin)
        self._restart()

    def reset(self) -> None:
        pass

    def refresh(self, tick: int, z: np.ndarray | None, stamp: float) -> None:
        pass

    def update(self, tick: int, z: np.ndarray | None, stamp: float) -> None:
        pass

    def forecast(self) -> None:
        pass

    def learn(self) -> None:
        pass

    def predict(self) -> None:
        pass

    def interpolate(self) -> None:
        pass

    def score(self) -> None:
        pass

    def horizon(self, tick: int) -> np.ndarray:
        """r_{tick+1} … r_{tick+N}: (N, d) centred, or (N, 3) in the workspace after ``place``."""
        return self.horizons(tick, 1)[0]

    def horizons(self, tick: int, count: int) -> np.ndarray:
        """:meth:`horizon` of ticks tick … tick + count − 1 as one read-only (count, N, d)
        array (:func:`windows`; a view of an array never changed)."""
        points = self._cover(tick + 1, tick + count + self.N)
        return windows(points, tick + 1 - self._w0, count, self.N)
