"""The closed loop: heart → sensor → predictor → reference → MPC → cancellation → plant.

Time is integer ticks of ``Ts`` (seconds = tick·Ts). Each tick ``i``:

1. the newest sensor sample that has *arrived* by ``i·Ts`` is known;
2. every ``downsample`` ticks, or on each raw sample of a slow sensor (:mod:`sim.loop.clock`),
   the reference is refreshed with it (the predictor runs; a tick with no new sample since the
   last refresh is a missing sample for the predictor) — by default pipelined over four
   ticks: the gate and the predictor's update, its learning, its forecast, then the
   interpolation, guard and placement on the refresh tick, so that no tick carries more than
   one slice of a refresh (``LoopSettings.pipelined_refresh``);
3. the reference gives the N points ``r_{i+1..i+N}``, placed in the robot's workspace:
   ``r = y0 + offset + E·r_c`` (``r_c`` centred heart coordinates);
4. the encoders quantise ``q``, the observer estimates ``x̂ = [q − q0; q̇]``;
5. the MPC computes ``τ_mpc``; the cancellation adds ``ĝ + Ĉq̇ + f̂`` at the estimated state;
6. the plant integrates one tick with the (clipped) torque held.

Steps 1–3 are open-loop — the heart and its sensor do not see the robot — but they run tick
by tick all the same, interleaved with steps 4–6 (:meth:`OpenLoop.segments`): each slice of a
refresh runs on the tick it is charged to, between two control ticks, as in a controller with
one thread, so that its time is taken with the caches the control ticks leave behind. The
control ticks between two slices run one at a time from Python, or, for a compiled controller
on the compiled plant, in one C call (:mod:`sim.loop.ticks`). The
heart's and the sensor's samples are made a block at a time (:mod:`sim.loop.streams`), and the
records are kept per chunk of ≈ 10 s of ticks (:mod:`sim.loop.results`).

Memory is flat in run length: the sensor stream and the POI truth are read per chunk
(:mod:`sim.loop.streams`), results accumulate as running statistics (:mod:`sim.loop.metrics`)
and a fixed-size decimated trace, and every tick can go to an NPZ file as the run goes
(:mod:`sim.loop.trace`). The garbage collector is frozen and disabled during the run.

The POI trajectory is centred on its mean over the run and placed at the end-effector's home
position plus ``poi_offset``. A 1-D motion moves along the x axis. The error is
``p_ee(q_{i+1}) − p_poi((i+1)·Ts)``.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import gc
import math
import time
from collections.abc import Callable, Iterator

import numpy as np

from robots import LinearArm, Robot
from sim.loop.clock import PredictorClock, arrival_tick, predictor_clock
from sim.loop.results import CHARGED, LoopResult, Recorder
from sim.loop.settings import LoopSettings
from sim.loop.streams import BLOCK, ArrayTruth, SampleSource, StreamCursor, as_samples
from sim.loop.ticks import compiled_ticks, run_ticks
from sim.plant import HardwareSettings, ModelMismatch, ObserverSettings, PlantSettings
from sim.plant.tick import make_tick

clock = time.perf_counter_ns
#: Ticks from a refresh's update to its interpolation when the refresh is pipelined: the
#: update, the learning, the forecast and the interpolation each on a tick of its own.
REFRESH_LAG = 3


def poi_truth(source, n_ticks: int, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """The source's mean over the run, and its centred position at ticks 0 … n_ticks−1.

    Returns ``(center (d,), truth (n_ticks, d))`` in metres.
    """
    p = np.asarray(source.position(np.arange(n_ticks) * Ts), dtype=float).reshape(n_ticks, -1)
    center = np.nanmean(p, axis=0)
    if not np.all(np.isfinite(center)):
        raise ValueError("the heart motion has no finite sample over the run")
    return center, p - center


def newest_arrived(arrival: np.ndarray, n_ticks: int, Ts: float) -> np.ndarray:
    """Index of the newest sample arrived by each tick's time (−1 before the first)."""
    return np.searchsorted(arrival, np.arange(n_ticks) * Ts + 1e-12, side="right") - 1


class RawQueue:
    """A sensor's raw samples in arrival order, read a block at a time.

    ``tick()`` is the tick at which the next sample has arrived (None when none is left);
    ``pop()`` returns it as ``(t, z)``.
    """

    def __init__(self, samples: SampleSource, Ts: float) -> None:
        self.samples, self.n, self.Ts = samples, len(samples), Ts
        self.k = 0
        self._start, self._block = 0, samples.block(0, min(BLOCK, self.n))

    def _row(self) -> int:
        if self.k - self._start >= self._block[0].size:
            self._start = self.k
            self._block = self.samples.block(self.k, min(self.k + BLOCK, self.n))
        return self.k - self._start

    def tick(self) -> int | None:
        if self.k >= self.n:
            return None
        return arrival_tick(float(self._block[2][self._row()]), self.Ts)

    def pop(self) -> tuple[float, np.ndarray]:
        row = self._row()
        self.k += 1
        return float(self._block[0][row]), self._block[1][row]


class OpenLoop:
    """Steps 1–3, tick by tick: each refresh slice runs on its own tick, between control ticks.

    As a controller with one thread runs it; its time is charged to that tick.

    Parameters
    ----------
    reference
        ``update(tick, z, stamp)``, ``learn()``, ``predict()``, ``interpolate()``,
        ``horizons(tick, count)`` and optionally ``score()``
        (:mod:`rhmpc.control.reference`), placed in the workspace.
    stream
        The sensor's sample source (:mod:`sim.loop.streams`).
    center : ndarray
        The POI's mean over the run, subtracted from every sample [m].
    settings : LoopSettings
    hold : ndarray, shape (N, 3), optional
        The points used before the first sample (the POI's mean position; default the
        origin) [m].
    clock : PredictorClock, optional
        When the predictor runs (:mod:`sim.loop.clock`); default every ``downsample`` ticks.

    Notes
    -----
    The slices wait in a queue, in the order they run, each with its tick: a refresh on tick r
    queues its forecast-error bookkeeping (tick r + 1 when pipelined), then the next refresh's
    update, learning and forecast (ticks r' − 3, r' − 2, r' − 1, not before r) and its
    interpolation (tick r'). :meth:`segments` runs those due on a tick before it yields the
    references from that tick on. A slice queued behind a later one waits for it: when the next
    refresh is due on tick r + 1 (a burst of arrivals, or ``downsample`` ≤ 3), its update,
    learning and forecast run on tick r + 1 after the bookkeeping, up to five slices on one
    tick. The order of the calls, hence every result, is that of the refresh run at once.
    """

    #: The most missing samples filled before a sample after a gap in its time stamps.
    MAX_FILL = 50
    #: The most ticks whose references are fetched at once (a period without a refresh, such
    #: as after a recording's last sample, is fetched in pieces of this many ticks).
    PERIOD = 256
    # the parts of a refresh (indices into CHARGED)
    _UPDATE, _LEARN, _FORECAST, _INTERPOLATE, _SCORE = range(len(CHARGED))

    def __init__(self, reference, stream, center: np.ndarray, settings: LoopSettings,
                 hold: np.ndarray | None, clock: PredictorClock | None = None) -> None:
        self.reference, self.center, self.settings = reference, center, settings
        self.hold = np.zeros((settings.horizon, 3)) if hold is None else hold
        self.score = getattr(reference, "score", None)  # optional: the predictor's bookkeeping
        self.clock = clock or PredictorClock("downsample", settings.downsample * settings.Ts,
                                             settings.downsample, math.inf)
        # ticks from a refresh's update to its interpolation: update, learning, forecast and
        # interpolation each on its own tick when pipelined, all on the refresh tick otherwise
        self.lag = REFRESH_LAG if settings.pipelined_refresh else 0
        self.slices: collections.deque = collections.deque()  # (tick, part), run by _run
        self._steps = {self._LEARN: reference.learn, self._FORECAST: reference.predict,
                       self._INTERPOLATE: reference.interpolate, self._SCORE: self.score}
        if self.clock.mode == "sensor":
            self.queue = RawQueue(self.clock.raw, settings.Ts)
            self.last_stamp: float | None = None
            first = self.queue.tick()
            self.next = math.inf if first is None else first + self.lag
        else:
            self.cursor = StreamCursor(as_samples(stream))
            self.last = -1  # index of the newest sample given to the reference
            self.next = 0
        self._schedule(self.next, after=-self.lag)  # run on tick 0 when due before it

    def update(self, tick: int) -> int:
        """Feed the reference the newest sample arrived by ``tick`` (None if none is new).

        Returns the time [ns] of the controller's part. The sensor's delivery is not timed: it
        is the simulated world, which makes the samples a block at a time.
        """
        z, stamp = self._sample(tick)
        t_start = clock()
        self.reference.update(tick, z, stamp)
        return clock() - t_start

    def segments(self, c0: int, c1: int, charged: tuple[list[int], ...],
                 horizons: list) -> Iterator[tuple[int, np.ndarray, int]]:
        """Yield ``(i, refs, address)`` over ticks c0 … c1 − 1, in order: ``refs`` holds
        r_{i+1..i+N} of ticks i … i + count − 1 (a read-only (count, N, d) view, d = 3 once
        placed, whose first point is at ``address`` in memory), after the slices due on tick i
        have run; none is due on the others, so their control ticks may run back to back. The
        slices' ns go to ``charged[part][i − c0]`` (:data:`CHARGED`: the predictor's update
        with the gate, its learning, its forecast, the interpolation with the guard, the
        forecast-error bookkeeping), each refresh's ``(tick, points)`` to ``horizons``."""
        slices, i, end = self.slices, c0, c0
        while i < c1:
            refreshed = False
            while slices and slices[0][0] <= i:
                tick, part = slices.popleft()
                charged[part][i - c0] += self._run(tick, part)
                if part == self._INTERPOLATE:
                    refreshed = True
                    self._refreshed(i)
            if refreshed or i == end:
                count = min(self.next, c1, i + self.PERIOD) - i
                if count < 1:
                    raise RuntimeError(f"no tick to run at tick {i} (next refresh {self.next})")
                block = self.reference.horizons(i, count)
                if refreshed:  # a copy: the block may be a copy of many windows
                    horizons.append((i, None if block is None else block[0].copy()))
                if block is None:  # before the first sample
                    block = np.broadcast_to(self.hold, (count, *self.hold.shape))
                first, end, stride = i, i + count, block.strides[0]
                address = block.__array_interface__["data"][0]
            j = min(slices[0][0], end) if slices else end  # the next tick with a slice
            yield i, block[i - first : j - first], address + (i - first) * stride
            i = j

    def plan(self, c0: int, c1: int) -> dict | None:
        """The slices :meth:`segments` would run on ticks c0 … c1 − 1, in the order it would run
        them, as arrays for a compiled refresh to run (:meth:`sim.loop.ticks.CompiledTicks.run`),
        without running them; None with the sensor clock, whose arrivals decide how many
        updates a slice makes.

        Returns ``row`` (tick − c0), ``part`` (:data:`CHARGED`'s index) and, for an update,
        ``tick`` (the tick it is for), ``z`` (its centred sample, a row per slice), ``stamp``
        [s] and ``fresh`` (a new sample, else none). The queue and the stream's cursor move on
        as if the slices had run: the next refreshes are queued on the interpolation's tick.
        """
        if not self.plannable:
            return None
        slices, at = self.slices, c0
        rows, parts, ticks, stamps, samples = [], [], [], [], {}  # samples: event -> z
        while slices and max(slices[0][0], at) < c1:
            tick, part = slices.popleft()
            at = max(tick, at)
            stamp = 0.0
            if part == self._UPDATE:
                z_k, stamp = self._sample(tick)
                if z_k is not None:
                    samples[len(rows)] = z_k
            rows.append(at - c0)
            parts.append(part)
            ticks.append(tick)
            stamps.append(stamp)
            if part == self._INTERPOLATE:
                self._refreshed(at)
        z, fresh = np.zeros((len(rows), self.center.shape[0])), np.zeros(len(rows), np.uint8)
        if samples:
            index = np.fromiter(samples, dtype=np.intp, count=len(samples))
            z[index], fresh[index] = np.array(list(samples.values())), 1
        return {"row": np.array(rows, dtype=np.intc), "part": np.array(parts, dtype=np.intc),
                "tick": np.array(ticks, dtype=np.int64), "z": z,
                "stamp": np.array(stamps, dtype=float), "fresh": fresh}

    @property
    def plannable(self) -> bool:
        """Whether :meth:`plan` can plan the slices ahead: not with the sensor's clock."""
        return self.clock.mode != "sensor"

    def _sample(self, tick: int) -> tuple[np.ndarray | None, float]:
        """The update of ``tick``'s arguments (:meth:`update`): the centred newest sample
        arrived by then and its time, or None and the tick's time when none is new."""
        j = self.cursor.newest(tick * self.settings.Ts + 1e-12)
        if j < 0 or j == self.last:
            return None, tick * self.settings.Ts
        self.last = j
        t_j, z_j = self.cursor.sample(j)
        return z_j - self.center, t_j

    def references(self, c0: int, c1: int, charged: tuple[list[int], ...],
                   horizons: list) -> Iterator[np.ndarray]:
        """:meth:`segments` tick by tick: r_{i+1..i+N} of ticks c0 … c1 − 1, each after the
        slices due on tick i have run."""
        for _, refs, _ in self.segments(c0, c1, charged, horizons):
            yield from refs

    def chunk(self, c0: int, c1: int) -> tuple[list, tuple[list[int], ...], list]:
        """:meth:`references` of ticks c0 … c1 − 1 at once, without control ticks between
        them (for a study of the open loop alone): the references, the ns charged to each tick
        for each part, each refresh's ``(tick, points)``."""
        charged = tuple([0] * (c1 - c0) for _ in CHARGED)
        horizons: list = []
        return list(self.references(c0, c1, charged, horizons)), charged, horizons

    def finish(self) -> None:
        """Run, untimed, what a pipelined refresh queued past the last tick run (its
        bookkeeping, the next refresh's update, learning and forecast; not an interpolation):
        a pipelined refresh makes them as soon as it has placed its points. Without the
        pipeline nothing is made ahead, and nothing runs."""
        if self.lag:
            for tick, part in self.slices:
                if part != self._INTERPOLATE:
                    self._run(tick, part)
        self.slices.clear()

    def _run(self, tick: int, part: int) -> int:
        """Run the slice ``part`` (:data:`CHARGED`'s index) queued on ``tick``; its time [ns]:
        the update's own (:meth:`update`, :meth:`_arrivals`), the others' whole call."""
        if part == self._UPDATE:
            return self._arrivals(tick) if self.clock.mode == "sensor" else self.update(tick)
        step = self._steps[part]
        t_start = clock()
        step()
        return clock() - t_start

    def _refreshed(self, i: int) -> None:
        """After the refresh on tick ``i``: queue its bookkeeping (on the next tick when
        pipelined) and the next refresh."""
        if self.score is not None:
            self.slices.append((i + (1 if self.lag else 0), self._SCORE))
        if self.clock.mode == "sensor":
            arrival = self.queue.tick()
            self.next = math.inf if arrival is None else max(arrival + self.lag, i + 1)
        else:
            self.next = i + self.settings.downsample
        self._schedule(self.next, after=i)

    def _schedule(self, r: float, after: int) -> None:
        """Queue the update, the learning and the forecast of the refresh on tick ``r`` (ticks
        r − lag, r − lag + 1 and r − 1 when pipelined, not before ``after``) and the refresh."""
        if r == math.inf:
            return
        ticks = [r - self.lag, r - self.lag + 1, r - 1] if self.lag else [r, r, r]
        t0, t1, t2 = (max(t, after) for t in ticks)
        self.slices.extend(((t0, self._UPDATE), (t1, self._LEARN), (t2, self._FORECAST),
                            (r, self._INTERPOLATE)))

    def _arrivals(self, tick: int) -> int:
        """Feed every raw sample arrived by ``tick``, each once, with its own stamp; a gap in
        the stamps is filled with missing samples first. Returns the time spent [ns]."""
        spent, dt, reference = 0, self.clock.dt, self.reference
        while (arrived := self.queue.tick()) is not None and arrived <= tick:
            t_k, z_k = self.queue.pop()
            fills = 0 if self.last_stamp is None else round((t_k - self.last_stamp) / dt) - 1
            t_start = clock()
            for _ in range(min(max(fills, 0), self.MAX_FILL)):
                reference.update(tick, None, t_k)
                reference.predict()
            reference.update(tick, z_k - self.center, t_k)
            if self.queue.tick() is not None and self.queue.tick() <= tick:
                reference.predict()  # a bunch of arrivals: each gated against its forecast
            spent += clock() - t_start
            self.last_stamp = t_k
        return spent


@contextlib.contextmanager
def quiet_gc() -> Iterator[None]:
    """No garbage collection inside the 2-kHz loop (a collection stalls it for milliseconds):
    what exists is frozen, never scanned again, and the collector is off until the end."""
    was_enabled = gc.isenabled()
    gc.freeze()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()
        gc.unfreeze()


def run_closed_loop(
    robot: Robot,
    arm: LinearArm,
    controller,
    reference,
    truth,
    center: np.ndarray | None,
    stream,
    settings: LoopSettings,
    *,
    plant_settings: PlantSettings | None = None,
    mismatch: ModelMismatch | None = None,
    observer_settings: ObserverSettings | None = None,
    hardware: HardwareSettings | None = None,
    progress: Callable[[int], None] | None = None,
    trace_file: str | None = None,
    yardstick: Callable[[np.ndarray, np.ndarray, np.ndarray], object] | None = None,
    chunk_ticks: int = 20_000,
) -> LoopResult:
    """Run the closed loop for ``settings.duration``, in chunks of ≈ 10 s of ticks.

    Parameters
    ----------
    controller
        ``step(x, ref) -> τ_mpc`` and a ``stats`` mapping
        (:class:`rhmpc.control.mpc.RecedingHorizonMPC`).
    reference
        ``place(origin)``, the slices of a refresh ``update(tick, z, stamp)``, ``learn()``,
        ``predict()``, ``interpolate()`` and optionally ``score()``, and ``horizons(tick,
        count)`` → the points of ticks tick … tick + count − 1 as one (count, N, 3) array, None
        before the first sample (:mod:`rhmpc.control.reference`); the loop places it at the
        workspace anchor before the run.
    truth, center
        The centred POI truth over at least ``ticks + horizon + 1`` ticks: an array from
        :func:`poi_truth` with its ``center``, or an object with ``window(i0, i1)``, ``n_ticks``
        and ``center`` (:class:`sim.loop.streams.SourceTruth`; ``center`` is then ignored).
    stream
        Sensor samples: arrays ``t`` [s], ``z`` (n, d) [m] (NaN = missing) and ``arrival`` [s],
        or a sample source of :mod:`sim.loop.streams` read block by block.
    plant_settings, mismatch, observer_settings, hardware
        The robot's side of the tick (:func:`sim.plant.tick.make_tick`).
    progress
        Called with the number of ticks done, every 2000 ticks.
    trace_file
        Write every tick to this NPZ file as the run goes (:class:`sim.loop.trace.TraceFile`).
    yardstick
        A reference computation ``yardstick(x̂, r, u_{−1})`` (the gain tick g of
        :class:`rhmpc.control.yardstick.GainTick`) timed on every 64th tick after the controller
        (after the call, with the compiled ticks), with the tick's own inputs, so that tick
        times can be stated as ratios to it measured in the same run
        (``LoopResult.yardstick_us``); not part of the tick, its result is not used.
    chunk_ticks
        Ticks per chunk of records (rounded down to a multiple of ``downsample``, at least one
        period).
    """
    n, N, ds = settings.ticks, settings.horizon, settings.downsample
    if not hasattr(truth, "window"):
        truth = ArrayTruth(truth, center)
    if truth.n_ticks < n + N + 1:
        raise ValueError(f"truth covers {truth.n_ticks} ticks, the run needs {n + N + 1}")
    anchor = arm.y0 + np.asarray(settings.poi_offset, dtype=float)
    reference.place(anchor)
    side = make_tick(robot, arm, settings.Ts, plant_settings, mismatch, observer_settings,
                     hardware)
    record = Recorder(robot, settings, truth, anchor, trace_file)
    chunk = ds * max(1, chunk_ticks // ds)  # ticks per chunk of records (a multiple of ds)
    with quiet_gc():
        try:
            open_loop = OpenLoop(reference, stream, truth.center, settings, np.tile(anchor, (N, 1)),
                                 predictor_clock(settings, stream))
            compiled, loop = compiled_ticks(controller, side, settings)
            slices = None  # the refresh slices run from the compiled ticks, where they can
            if compiled is not None and hasattr(reference, "slices") and open_loop.plannable:
                slices, loop = reference.slices(open_loop.hold), "compiled with the refresh"
            u_prev = None
            for c0 in range(0, n, chunk):
                c1 = min(c0 + chunk, n)
                charged = (np.zeros((len(CHARGED), c1 - c0), dtype=np.int64)  # written by C
                           if slices is not None else tuple([0] * (c1 - c0) for _ in CHARGED))
                horizons: list = []
                log = record.start_chunk(c1 - c0, charged, u_prev)
                if slices is not None:
                    horizons = compiled.run_planned(c0, c1, open_loop.plan(c0, c1), slices,
                                                    log, yardstick, progress)
                else:
                    segments = open_loop.segments(c0, c1, charged, horizons)
                    if compiled is not None:
                        compiled.run(c0, segments, log, yardstick, progress)
                    else:
                        run_ticks(side, controller, c0, segments, log, yardstick, progress)
                u_prev = log["u_prev"]
                record.end_chunk(c0, c1, log, horizons)
            open_loop.finish()
        finally:
            record.close()
    counts = dict(getattr(getattr(reference, "predictor", None), "counts", {}) or {})
    note = f" ({side.dynamics_note})" if side.dynamics_note else ""
    return record.result(controller_stats(controller), counts, side.dynamics + note, loop)


def controller_stats(controller) -> dict:
    """The controller's counters as a plain dict, with ``fallback_total``."""
    stats_obj = getattr(controller, "stats", None)
    if dataclasses.is_dataclass(stats_obj):
        stats = dataclasses.asdict(stats_obj)
        stats["fallback_total"] = int(getattr(stats_obj, "fallback_total", 0))
        return stats
    return dict(stats_obj or {})
