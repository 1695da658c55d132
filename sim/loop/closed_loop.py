"""The closed loop: heart → sensor → controller (reference, observer, MPC, cancellation) → plant.

Time is integer ticks of ``Ts`` (seconds = tick·Ts). Each tick ``i``:

1. every sample due on tick i refreshes the controller's reference, in one call each
   (``controller.refresh``): every ``downsample`` ticks the newest sample delivered to the
   control rate, or each raw sample of a slow sensor on the tick it arrives
   (:class:`Refreshes`, :mod:`rhmpc.sim.loop.clock`);
2. the controller steps from the plant's encoder angles (``controller.step``: observer, MPC on
   the reference's points r_{i+1..i+N}, cancellation), and returns the torque;
3. the plant integrates one tick with that torque held.

Between two refreshes the ideal plant runs steps 2–3 of the controller's library in C
(``ArmPlant.run_ticks``, ``plant_run`` in ``sim/plant/chain.c``): the same calls in the same
order, so the records are those of the ticks one at a time, to the last bit.

The heart and its sensor do not see the robot; their samples are made a block at a time
(:mod:`rhmpc.sim.loop.streams`). The controller is a :class:`rhmpc.control.controller.Controller`,
or the exported C controller behind the same two calls (:mod:`rhmpc.control.export`); the loop uses
nothing else of it but what it reports (its torques, state estimate, points and timings).

Memory is flat in run length: the sensor stream and the POI truth are read per chunk
(:mod:`rhmpc.sim.loop.streams`), results accumulate as running statistics
(:mod:`rhmpc.sim.loop.metrics`) and a fixed-size decimated trace, and every tick can go to an NPZ
file as the run goes (:mod:`rhmpc.sim.loop.trace`). The garbage collector is frozen and disabled
during the run.

The POI trajectory is placed in the workspace (``LoopSettings.placement``): by default its mean
over the run at the end-effector's home position plus ``poi_offset`` (a 1-D motion along x).
The samples reach the reference as measured, which places them (``place(anchor, center)``).
The error is ``p_ee(q_{i+1}) − p_poi((i+1)·Ts)``: at every tick for a synthetic motion, whose
truth is continuous; at the instants of its samples for a recording (``measured``).
"""

from __future__ import annotations

import contextlib
import gc
import itertools
import math
import time
from collections.abc import Callable, Iterable, Iterator

import numpy as np

from rhmpc.sim.loop.clock import PredictorClock, arrival_tick
from rhmpc.sim.loop.exact import ArrayTruth
from rhmpc.sim.loop.metrics import warm_ns
from rhmpc.sim.loop.results import (
    YARDSTICK_EVERY,
    YARDSTICK_PHASE,
    LoopResult,
    Recorder,
    event_counts,
)
from rhmpc.sim.loop.settings import LoopSettings
from rhmpc.sim.loop.streams import StreamCursor
from rhmpc.sim.recordings.points import PointsAt
from rhmpc.sim.sensors.stream import BLOCK, SampleSource, as_samples

clock = time.perf_counter_ns
#: Ticks between two calls of ``progress``.
PROGRESS = 2000


def poi_truth(source, n_ticks: int, Ts: float) -> tuple[np.ndarray, np.ndarray]:
    """The source's mean over the run, and its centred position at ticks 0 … n_ticks−1.

    Returns ``(center (d,), truth (n_ticks, d))`` in metres.
    """
    p = np.asarray(source.position(np.arange(n_ticks) * Ts), dtype=float).reshape(n_ticks, -1)
    center = np.nanmean(p, axis=0)
    if not np.all(np.isfinite(center)):
        raise ValueError("the heart motion has no finite sample over the run")
    return center, p - center


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


class Refreshes:
    """The samples that refresh the reference on each tick: the sensor's delivery to the loop.

    With the ``"downsample"`` clock, every ``downsample`` ticks from tick 0: the newest sample
    arrived by then, stamped with its measurement time (None and the tick's time when no sample
    is new). With the ``"sensor"`` clock, each raw sample once, on the tick it arrives, with its
    own stamp; a gap in the stamps is first filled with missing samples (at most
    :attr:`MAX_FILL`), so that the predictor's clock keeps its period. With ``points`` (the
    other tracked points of a recording), each refresh also carries the other points measured
    at its stamp (None where none was measured then). Samples are as measured.
    """

    #: The most missing samples filled into one gap of the stamps.
    MAX_FILL = 50

    def __init__(self, stream, settings: LoopSettings, clock: PredictorClock,
                 points: PointsAt | None = None) -> None:
        self.Ts, self.clock, self.points = settings.Ts, clock, points
        self.sensor = clock.mode == "sensor"
        if self.sensor:
            self.queue = RawQueue(clock.raw, settings.Ts)
            self.last_stamp: float | None = None
            first = self.queue.tick()
            self.next = math.inf if first is None else first
        else:
            self.cursor = StreamCursor(as_samples(stream))
            self.last = -1  # index of the newest sample given to the reference
            self.period = settings.downsample
            self.next = 0

    def due(self, tick: int) -> Iterator[tuple[np.ndarray | None, float, np.ndarray | None]]:
        """``(z, stamp, others)`` of every refresh on ``tick``, in order (call once per tick,
        in order); ``others`` is None without ``points``."""
        for z, stamp in self._due(tick):
            others = None if self.points is None or z is None else self.points.at(stamp)
            yield z, stamp, others

    def _due(self, tick: int) -> Iterator[tuple[np.ndarray | None, float]]:
        if tick < self.next:
            return
        if not self.sensor:
            self.next = tick + self.period
            yield self._newest(tick)
            return
        queue, dt = self.queue, self.clock.dt
        while (arrived := queue.tick()) is not None and arrived <= tick:
            t_k, z_k = queue.pop()
            fills = 0 if self.last_stamp is None else round((t_k - self.last_stamp) / dt) - 1
            for _ in range(min(max(fills, 0), self.MAX_FILL)):
                yield None, t_k
            self.last_stamp = t_k
            yield z_k, t_k
        arrived = queue.tick()
        self.next = math.inf if arrived is None else arrived

    def _newest(self, tick: int) -> tuple[np.ndarray | None, float]:
        """The newest sample arrived by ``tick`` and its time, or None and the tick's
        time when none is new."""
        j = self.cursor.newest(tick * self.Ts + 1e-12)
        if j < 0 or j == self.last:
            return None, tick * self.Ts
        self.last = j
        t_j, z_j = self.cursor.sample(j)
        return z_j, t_j


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


def _note_outliers(before: tuple[int, int], after: tuple[int, int], stamp: float,
                   log: dict) -> None:
    """The stamp of a sample the gate rejected, or of the previous one if it was retracted
    (``log["outliers"]``); the newest accepted sample's stamp in ``log["last_stamp"]``."""
    if after[0] > before[0]:
        log["outliers"].append(stamp)
        return
    if after[1] > before[1] and log["last_stamp"] is not None:
        log["outliers"].append(log["last_stamp"])
    log["last_stamp"] = stamp


def run_closed_loop(plant, controller, truth, stream, settings: LoopSettings,
                    clock: PredictorClock, *, anchor: np.ndarray, robot,
                    progress: Callable[[int], None] | None = None,
                    trace_file: str | None = None,
                    yardstick: Callable[[np.ndarray, np.ndarray, np.ndarray], object] | None = None,
                    chunk_ticks: int = 20_000, marks: Iterable[int] = (),
                    points: PointsAt | None = None,
                    measured: tuple[np.ndarray, np.ndarray] | None = None) -> LoopResult:
    """Run the closed loop for ``settings.duration``, in chunks of ≈ 10 s of ticks.

    Parameters
    ----------
    plant
        ``encoders()``, ``step(tau)``, ``q`` (:mod:`rhmpc.sim.plant`).
    controller
        ``refresh(tick, z, stamp)``, ``step(tick, q) -> τ``, with ``u``, ``tau_command``,
        ``x_hat``, ``horizon(tick)``, ``step_ns``, ``refresh_ns`` and ``stats``
        (:class:`rhmpc.control.controller.Controller`), its reference placed at ``anchor``
        with the truth's ``center`` (``reference.place(anchor, truth.center)``).
    truth
        The centred POI truth over at least ``ticks + N + 1`` ticks: an object with
        ``window(i0, i1)``, ``n_ticks`` and ``center``
        (:class:`rhmpc.sim.loop.streams.SourceTruth`), or an array (with ``center`` zero).
    stream
        Sensor samples: arrays ``t`` [s], ``z`` (n, d) [m] (NaN = missing) and ``arrival`` [s],
        or a sample source of :mod:`rhmpc.sim.loop.streams` read block by block.
    clock
        When the reference refreshes (:func:`rhmpc.sim.loop.clock.predictor_clock`).
    anchor : ndarray (3,)
        Where the motion's mean sits in the workspace [m].
    robot
        The plant's robot (forward kinematics of the records).
    progress
        Called with the number of ticks done, every :data:`PROGRESS` ticks.
    trace_file
        Write every tick to this NPZ file as the run goes (:class:`rhmpc.sim.loop.trace.TraceFile`).
    yardstick
        A reference computation ``yardstick(x̂, r, u_{−1})`` (the gain tick g of
        :class:`rhmpc.timing.yardstick.GainTick`) timed on every 64th tick after the controller,
        with the tick's own inputs, so that tick times can be stated as ratios to it measured in
        the same run (``LoopResult.yardstick_us``); not part of the tick, its result is not used.
    chunk_ticks
        Ticks per chunk of records.
    marks
        Ticks at which a chunk also ends and the controller's and the plant's event counts are
        read (:func:`rhmpc.sim.loop.results.event_counts`): the result's ``segments`` then hold, for
        each stretch between two marks, its largest error, its joint envelope and the counts
        at its end (how an injected fault is measured, :mod:`rhmpc.sim.loop.faults`).
    points
        The other tracked points of a recording, given with each sample to the controller's
        refresh (``others``: what a multi-point predictor reads).
    measured
        A recording's own samples ``(t [s], z (n, d) [m])`` in the run's time, uncentred: the
        run is then scored at their instants (:class:`rhmpc.sim.loop.metrics.MeasuredScore`), and
        the all-tick score against their interpolant is kept beside it.
    """
    n, N = settings.ticks, controller.N
    if not hasattr(truth, "window"):
        truth = ArrayTruth(truth)
    if truth.n_ticks < n + N + 1:
        raise ValueError(f"truth covers {truth.n_ticks} ticks, the run needs {n + N + 1}")
    refreshes = Refreshes(stream, settings, clock, points)
    marks = [int(m) for m in marks]
    segmented = bool(marks)  # also when every mark is an end of the run (a fault from 0 to n)
    record = Recorder(robot, settings, N, truth, anchor, trace_file, clock, segmented, measured)
    with quiet_gc():
        try:
            for c0, c1 in chunks(n, chunk_ticks, marks):
                log = record.start_chunk(c0, c1)
                _run_ticks(plant, controller, refreshes, c0, c1, log, yardstick, progress)
                record.end_chunk(c0, c1, log)
                if segmented:
                    record.count(event_counts(controller, plant))
        finally:
            record.close()
    return record.result(controller)


def chunks(n: int, size: int, marks: Iterable[int] = ()) -> list[tuple[int, int]]:
    """(c0, c1) of the chunks of ticks 0 … n − 1: every ``size`` ticks, and at each mark."""
    edges = sorted({*range(0, n, size), *(m for m in marks if 0 < m < n), n})
    return list(itertools.pairwise(edges))


def _run_ticks(plant, controller, refreshes: Refreshes, c0: int, c1: int, log: dict,
               yardstick, progress) -> None:
    """Ticks c0 … c1 − 1 (the module's steps 1–3), written into the chunk's records ``log``
    (:meth:`~rhmpc.sim.loop.results.Recorder.start_chunk`): the ticks with nothing for Python
    (:func:`_alone_until`) in C where the plant and the controller can (the ideal plant's
    ``run_ticks`` with the controller's library), the others one at a time."""
    in_c = hasattr(type(plant), "run_ticks") and hasattr(controller, "library_loop")
    ahead = plant.run_ticks if in_c else None  # not a wrapper's, nor for another controller
    rows = ("q", "ref0", "u", "tau", "cmd", "step_ns")
    i = c0
    while i < c1:
        end = i if ahead is None else _alone_until(i, c1, refreshes, controller, yardstick,
                                                     progress)
        if end > i:
            ahead(controller, i, {k: log[k][i - c0:end - c0] for k in rows})
            log["u_prev"], i = controller.u, end
            continue
        _run_tick(plant, controller, refreshes, i, i - c0, log, yardstick)
        if progress is not None and (i + 1) % PROGRESS == 0:
            progress(i + 1)
        i += 1


def _alone_until(i: int, c1: int, refreshes: Refreshes, controller, yardstick,
                 progress) -> int:
    """The first tick from ``i`` on that needs Python: a refresh due, the yardstick's or the
    progress's tick, the exact reference's next points (``controller.steps_alone``), or c1."""
    end = min(c1, refreshes.next, controller.steps_alone() + 1)
    if yardstick is not None:
        end = min(end, i + (YARDSTICK_PHASE - i) % YARDSTICK_EVERY)
    if progress is not None:
        end = min(end, i + (PROGRESS - 1 - i) % PROGRESS)
    return int(end) if end > i else i


def _run_tick(plant, controller, refreshes: Refreshes, i: int, k: int, log: dict,
              yardstick) -> None:
    """Tick ``i`` (the module's steps 1–3) into row ``k`` of the chunk's records ``log``."""
    spent, refreshed = 0, False
    for z, stamp, others in refreshes.due(i) if i >= refreshes.next else ():
        before = controller.outliers
        controller.refresh(i, z, stamp, others)
        spent += controller.refresh_ns
        log["refresh_each_ns"].append(controller.refresh_ns)
        refreshed = True
        if z is not None:
            _note_outliers(before, controller.outliers, stamp, log)
        log["samples"].append((stamp, z))
    tau = controller.step(i, plant.encoders())
    plant.step(tau)
    log["step_ns"][k], log["refresh_ns"][k] = controller.step_ns, spent
    points = controller.horizon(i)
    if refreshed:
        log["horizons"].append((i, points.copy()))
    log["ref0"][k] = points[0]
    u, u_prev = controller.u, log["u_prev"]
    if yardstick is not None and i % YARDSTICK_EVERY == YARDSTICK_PHASE \
            and u_prev is not None:
        log["yardstick_ns"].append(warm_ns(yardstick, controller.x_hat, points, u_prev))
    log["u_prev"] = u
    log["u"][k], log["tau"][k], log["cmd"][k] = u, tau, controller.tau_command
    log["q"][k] = plant.q
