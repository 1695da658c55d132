"""The closed loop: heart → sensor → predictor → reference → MPC → cancellation → plant.

Time is integer ticks of ``Ts`` (seconds = tick·Ts). Each tick ``i``:

1. the newest sensor sample that has *arrived* by ``i·Ts`` is known;
2. every ``downsample`` ticks the reference is refreshed with it (the predictor runs; a tick
   with no new sample since the last refresh is a missing sample for the predictor) — by default
   pipelined: the gate and the predictor's update on the tick before, the forecast,
   interpolation and guard on the refresh tick, so that no tick carries a whole refresh
   (``LoopSettings.pipelined_refresh``);
3. the reference gives the N points ``r_{i+1..i+N}``, placed in the robot's workspace:
   ``r = y0 + offset + E·r_c`` (``r_c`` centred heart coordinates);
4. the encoders quantise ``q``, the observer estimates ``x̂ = [q − q0; q̇]``;
5. the MPC computes ``τ_mpc``; the cancellation adds ``ĝ + Ĉq̇ + f̂`` at the estimated state;
6. the plant integrates one tick with the (clipped) torque held.

Steps 1–3 are open-loop — the heart and its sensor do not see the robot — so the loop makes them
for a chunk of ≈ 10 s of ticks ahead (same calls, same order, same results) and then runs steps
4–6 for that chunk (:mod:`sim.plant.tick`). Each part of a refresh is timed and charged to the
tick that would run it, so the per-tick timing still holds everything the controller does. The
first tick of a chunk runs with cold caches, a cost of simulating in chunks that a controller
running every tick does not have; it stays in the statistics, once per chunk (1 in 20 000 ticks,
below p99.9).

Memory is flat in run length: the sensor stream and the POI truth are read per chunk
(:mod:`sim.loop.streams`), results accumulate as running statistics (:mod:`sim.loop.metrics`)
and a fixed-size decimated trace, and every tick can go to an NPZ file as the run goes
(:mod:`sim.loop.trace`). The garbage collector is frozen and disabled during the run.

The POI trajectory is centred on its mean over the run and placed at the end-effector's home
position plus ``poi_offset``. A 1-D motion moves along the x axis. The error is
``p_ee(q_{i+1}) − p_poi((i+1)·Ts)``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import time
from collections.abc import Callable, Iterator

import numpy as np

from robots import LinearArm, Robot
from sim.loop.results import LoopResult, Recorder
from sim.loop.settings import LoopSettings
from sim.loop.streams import ArrayTruth, StreamCursor, as_samples
from sim.plant import HardwareSettings, ModelMismatch, ObserverSettings, PlantSettings
from sim.plant.tick import make_tick

clock = time.perf_counter_ns


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


class OpenLoop:
    """Steps 1–3 for a chunk of ticks: the references and the time charged to each tick.

    Parameters
    ----------
    reference
        ``update(tick, z, stamp)``, ``forecast()`` and ``horizons(tick, count)``
        (:mod:`rhmpc.control.reference`), placed in the workspace.
    stream
        The sensor's sample source (:mod:`sim.loop.streams`).
    center : ndarray
        The POI's mean over the run, subtracted from every sample [m].
    settings : LoopSettings
    hold : ndarray, shape (N, 3)
        The points used before the first sample (the POI's mean position) [m].
    """

    def __init__(self, reference, stream, center: np.ndarray, settings: LoopSettings,
                 hold: np.ndarray) -> None:
        self.reference, self.center, self.settings, self.hold = reference, center, settings, hold
        self.cursor = StreamCursor(as_samples(stream))
        self.last = -1  # index of the newest sample given to the reference
        if settings.pipelined_refresh:  # the first refresh's update, on tick −1
            self.update(-1)

    def update(self, tick: int) -> int:
        """Feed the reference the newest sample arrived by ``tick`` (None if none is new).

        Returns the time [ns] of the controller's part. The sensor's delivery is not timed: it
        is the simulated world, which makes the samples a block at a time.
        """
        Ts = self.settings.Ts
        j = self.cursor.newest(tick * Ts + 1e-12)
        new = j >= 0 and j != self.last
        t_j, z_j = self.cursor.sample(j) if new else (tick * Ts, None)
        t_start = clock()
        self.reference.update(tick, None if z_j is None else z_j - self.center, t_j)
        spent = clock() - t_start
        self.last = j if new else self.last
        return spent

    def chunk(self, c0: int, c1: int) -> tuple[list, list[int], list]:
        """References r_{i+1..i+N} of ticks c0 … c1 − 1, the ns charged to each, the forecasts.

        ``c0`` is a multiple of ``downsample``: every refresh of the chunk starts in it.
        """
        ds, pipelined, reference = self.settings.downsample, self.settings.pipelined_refresh, \
            self.reference
        refs, horizons, charged = [], [], [0] * (c1 - c0)
        for i in range(c0, c1, ds):
            spent = 0 if pipelined else self.update(i)
            t_start = clock()
            reference.forecast()
            # views; later refreshes replace the arrays they view, never change them
            period = reference.horizons(i, min(ds, c1 - i))
            charged[i - c0] += spent + clock() - t_start
            if pipelined and i + ds - 1 < c1:  # the next refresh's update, on its own tick
                charged[i + ds - 1 - c0] += self.update(i + ds - 1)
            horizons.append(period[0])  # the refresh's forecast from tick i
            refs.extend(self.hold if h is None else h for h in period)
        return refs, charged, horizons


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
    yardstick: Callable[[np.ndarray, np.ndarray], object] | None = None,
    chunk_ticks: int = 20_000,
) -> LoopResult:
    """Run the closed loop for ``settings.duration``, in chunks of ≈ 10 s of ticks.

    Parameters
    ----------
    controller
        ``step(x, ref) -> τ_mpc`` and a ``stats`` mapping
        (:class:`rhmpc.control.mpc.RecedingHorizonMPC`).
    reference
        ``place(origin)``, the two halves of a refresh ``update(tick, z, stamp)`` and
        ``forecast()``, and ``horizons(tick, count)`` → the (N, 3) points of ticks tick … tick +
        count − 1, None before the first sample (:mod:`rhmpc.control.reference`); the loop
        places it at the workspace anchor before the run.
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
        A reference computation ``yardstick(x̂, r)`` (the gain tick of
        :class:`rhmpc.control.yardstick.GainTick`) timed after the controller on every 16th tick,
        with the tick's own inputs, so that tick times can be stated as ratios to it measured in
        the same run (``LoopResult.yardstick_us``); not part of the tick, its result is not used.
    chunk_ticks
        Ticks per chunk (rounded down to a multiple of ``downsample``, at least one period).
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
    chunk = ds * max(1, chunk_ticks // ds)  # ticks per open-loop pass (a multiple of ds)
    with quiet_gc():
        try:
            open_loop = OpenLoop(reference, stream, truth.center, settings, np.tile(anchor, (N, 1)))
            for c0 in range(0, n, chunk):
                c1 = min(c0 + chunk, n)
                refs, charged, horizons = open_loop.chunk(c0, c1)
                log = record.start_chunk()
                log[1].extend(refs)  # r_{i+1..i+N} of every tick (views)
                run_ticks(side, controller, c0, c1, refs, charged, log, yardstick, progress)
                record.end_chunk(c0, c1, log, horizons)
        finally:
            record.close()
    counts = dict(getattr(getattr(reference, "predictor", None), "counts", {}) or {})
    note = f" ({side.dynamics_note})" if side.dynamics_note else ""
    return record.result(controller_stats(controller), counts, side.dynamics + note)


def run_ticks(side, controller, c0: int, c1: int, refs: list, charged: list[int], log: tuple,
              yardstick=None, progress=None) -> None:
    """Steps 4–6 for ticks c0 … c1 − 1, appending to the chunk's lists ``log``.

    ``side`` is the robot's side of the tick (:mod:`sim.plant.tick`); the tick's time is from
    the encoder reading to the commanded torque, plus what the open-loop part ``charged`` it.
    """
    q_log, _, tau_mpc_log, tau_log, tick_ns, yard_ns = log
    sense, actuate, advance, step = side.sense, side.actuate, side.advance, controller.step
    for i in range(c0, c1):
        t_start = clock()
        x_hat = sense()
        ref = refs[i - c0]
        u = step(x_hat, ref)
        tau = actuate(u)
        tick_ns.append(clock() - t_start + charged[i - c0])
        if yardstick is not None and i % 16 == 7:
            t_start = clock()
            yardstick(x_hat, ref)
            yard_ns.append(clock() - t_start)
        tau_mpc_log.append(u.tolist())
        tau_log.append(tau.tolist())
        advance()
        q_log.append(side.q.tolist())
        if progress is not None and (i + 1) % 2000 == 0:
            progress(i + 1)


def controller_stats(controller) -> dict:
    """The controller's counters as a plain dict, with ``fallback_total``."""
    stats_obj = getattr(controller, "stats", None)
    if dataclasses.is_dataclass(stats_obj):
        stats = dataclasses.asdict(stats_obj)
        stats["fallback_total"] = int(getattr(stats_obj, "fallback_total", 0))
        return stats
    return dict(stats_obj or {})
