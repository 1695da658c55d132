"""The closed loop: heart → sensor → predictor → reference → MPC → cancellation → plant.

Time is integer ticks of ``Ts`` (seconds = tick·Ts). Each tick ``i``:

1. the newest sensor sample that has *arrived* by ``i·Ts`` is known (``newest[i]``);
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
4–6 for that chunk. Keeping the two working sets apart saves ≈ 15 µs of a ≈ 90 µs tick;
each part of a refresh is timed and charged to the tick that would run it, so the per-tick
timing still holds everything the controller does. The first tick of a chunk runs with cold
caches (measured ≈ +130 µs: its forecast after the chunk's bookkeeping, its MPC after the
open-loop pass), a cost of simulating in chunks that a controller running every tick does not
have; it stays in the statistics, once per chunk (≈ 10 s: 1 in 20 000 ticks, below p99.9).

Memory is flat in run length: the sensor stream and the POI truth are read per chunk
(:mod:`sim.streams`), results accumulate as running statistics (:mod:`sim.metrics`) and a
fixed-size decimated trace, and every tick can go to an NPZ file as the run goes
(:mod:`sim.trace`). The garbage collector is frozen and disabled during the run.

The POI trajectory is centred on its mean over the run and placed at the end-effector's home
position plus ``poi_offset``. A 1-D motion moves along the x axis. The error is
``p_ee(q_{i+1}) − p_poi((i+1)·Ts)``.
"""

from __future__ import annotations

import dataclasses
import gc
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from robots import LinearArm, Robot
from sim.estimation import JointObserver, ObserverSettings
from sim.plant import ArmPlant, ModelMismatch, NonlinearityCancellation, PlantSettings
from sim.results import LoopResult, Recorder, embed3
from sim.streams import ArrayTruth, StreamCursor, as_samples

__all__ = ["LoopResult", "LoopSettings", "embed3", "poi_truth", "run_closed_loop"]


@dataclass(frozen=True)
class LoopSettings:
    """Timing and placement of a closed-loop run.

    Attributes
    ----------
    Ts : float
        Control period [s] (2 kHz in the paper).
    horizon : int
        N, reference points per tick [ticks] (50 = 25 ms).
    downsample : int
        Ticks between predictor updates (15 → 7.5 ms, Tuna et al. Fig. 9).
    prediction_points : int
        Points the predictor forecasts per update, before latency compensation (4).
    outlier_gate : float
        A sensor sample farther from its one-step forecast than max(this, 4 × the running RMS
        forecast miss) is treated as missing (echo outliers: the heart cannot jump millimetres in
        one 7.5 ms period); 0 disables [m]. Default 0.15 mm: 4σ of the one-step miss of the RLS
        predictors on the physical sonomicrometer's stream (RMS 0.029–0.047 mm on the six
        replicas, p99 0.07–0.09 mm; the running term's memory, 50 samples, is shorter than a
        beat and dips in diastole, so the floor holds the gate at the whole cycle's 4σ). A cycle
        slip (one wavelength on one range) moves the fix by 0.6–0.9 mm and the samples
        interpolated toward it by any fraction of that. History (60 s, seed 0, generalized): at
        1.5 mm (the former white-noise sensor's 2–6 mm outliers) a slip's sample passed and the
        RLS forecasts ran away, 11.5 mm max and 32 QP fallbacks; at 0.25 mm (the instrument's
        absolute accuracy) 2.7 mm; with the predictors' gap repair and retraction
        (:class:`rhmpc.control.reference.PredictedReference`) 0.74 mm. Over 30 min of the
        RR-driven run the gate at 0.25 / 0.20 / 0.15 / 0.10 mm left 14 / 7 / 0 / 3 forecast
        episodes above 2 mm (``docs/notes/issue-18-session3.md``). With a noisy sensor the
        4 × RMS term sets the radius instead.
    outlier_max_rejections : int
        After this many consecutive rejected samples the gate opens (a real jump, or a forecast
        gone wrong) until 20 samples in a row fall inside it again [samples]. Default 3: a slip
        lasts up to 8 ms and the causal playback adds one raw period (3.9 ms at 257 Hz), so it
        reaches ⌈11.9 / 7.5⌉ + 1 = 3 samples of the predictor.
    guard_speed : float
        Reference guard: forecasts farther from the last accepted sample than ``guard_margin +
        guard_speed · lead`` mean a diverged predictor; the reference then holds that sample and
        the predictor restarts. Above the fastest POI motion of the replicas (0.21 m/s); 0
        disables [m/s].
    guard_margin : float
        Constant part of the guard's reach [m].
    duration : float
        Simulated time [s].
    settling : float
        Initial time excluded from the metrics while the predictors converge [s].
    poi_offset : tuple[float, float, float]
        Mean POI position relative to the end-effector's home position [m].
    pipelined_refresh : bool
        Split each predictor refresh over two ticks, so that no tick carries all of it: the tick
        before a refresh tick runs the outlier gate and the predictor's update with the newest
        sample arrived by then, the refresh tick the forecast, interpolation and guard. False:
        the whole refresh on the refresh tick, with the newest sample arrived by that tick.
    """

    Ts: float = 0.5e-3
    horizon: int = 50
    downsample: int = 15
    prediction_points: int = 4
    outlier_gate: float = 0.15e-3
    outlier_max_rejections: int = 3
    guard_speed: float = 0.3
    guard_margin: float = 2e-3
    duration: float = 20.0
    settling: float = 5.0
    poi_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    pipelined_refresh: bool = True

    def __post_init__(self) -> None:
        if not (np.isfinite(self.Ts) and self.Ts > 0):
            raise ValueError(f"Ts must be > 0 [s], got {self.Ts!r}")
        for name in ("horizon", "downsample", "prediction_points"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        if not (np.isfinite(self.outlier_gate) and self.outlier_gate >= 0):
            raise ValueError(f"outlier_gate must be >= 0 [m], got {self.outlier_gate!r}")
        if not isinstance(self.outlier_max_rejections, int) or self.outlier_max_rejections < 0:
            raise ValueError(
                f"outlier_max_rejections must be an integer >= 0, got "
                f"{self.outlier_max_rejections!r}"
            )
        if not (np.isfinite(self.guard_speed) and self.guard_speed >= 0):
            raise ValueError(f"guard_speed must be >= 0 [m/s], got {self.guard_speed!r}")
        if not (np.isfinite(self.guard_margin) and self.guard_margin > 0):
            raise ValueError(f"guard_margin must be > 0 [m], got {self.guard_margin!r}")
        if self.prediction_points < 2:
            raise ValueError("prediction_points must be >= 2 (quadratic interpolation)")
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"duration must be > 0 [s], got {self.duration!r}")
        if not (0 <= self.settling < self.duration):
            raise ValueError(
                f"settling must be in [0, duration) [s], got {self.settling!r} "
                f"with duration {self.duration!r}"
            )
        if len(self.poi_offset) != 3 or not np.all(np.isfinite(self.poi_offset)):
            raise ValueError(f"poi_offset must be 3 finite numbers [m], got {self.poi_offset!r}")

    @property
    def ticks(self) -> int:
        return round(self.duration / self.Ts)

    @property
    def settling_ticks(self) -> int:
        return round(self.settling / self.Ts)


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
        and ``center`` (:class:`sim.streams.SourceTruth`; ``center`` is then ignored).
    stream
        Sensor samples: arrays ``t`` [s], ``z`` (n, d) [m] (NaN = missing) and ``arrival`` [s],
        or a sample source of :mod:`sim.streams` read block by block.
    progress
        Called with the number of ticks done, every 2000 ticks.
    trace_file
        Write every tick to this NPZ file as the run goes (:class:`sim.trace.TraceFile`).
    yardstick
        A reference computation ``yardstick(x̂, r)`` (the gain tick of
        :mod:`rhmpc.control.gain_tick`) timed after the controller on every 16th tick, with the
        tick's own inputs, so that tick times can be stated as ratios to it measured in the same
        run (``LoopResult.yardstick_us``); not part of the tick, its result is not used.
    chunk_ticks
        Ticks per chunk (rounded down to a multiple of ``downsample``, at least one period).
    """
    n, N, ds, Ts = settings.ticks, settings.horizon, settings.downsample, settings.Ts
    if not hasattr(truth, "window"):
        truth = ArrayTruth(truth, center)
    if truth.n_ticks < n + N + 1:
        raise ValueError(f"truth covers {truth.n_ticks} ticks, the run needs {n + N + 1}")
    anchor = arm.y0 + np.asarray(settings.poi_offset, dtype=float)

    reference.place(anchor)
    plant = ArmPlant(robot, Ts, plant_settings)
    plant.reset()
    cancel = NonlinearityCancellation(
        robot, mismatch, stiction_velocity=plant.settings.stiction_velocity
    )
    observer = JointObserver(arm, robot.encoder_resolution, observer_settings)
    velocity = observer.x[robot.nv :]  # a view of the estimate x̂ = [q − q0; q̇]
    resolution = robot.encoder_resolution
    inv_resolution = None if resolution is None else 1.0 / resolution
    encoder = np.empty(robot.nv)  # the quantised reading, rewritten every tick
    cursor = StreamCursor(as_samples(stream))
    center = truth.center

    record = Recorder(robot, settings, truth, anchor, trace_file)
    native_tick = None
    if plant.dynamics == "native":
        from sim.native import NativeTick

        native_tick = NativeTick(plant, cancel, observer, robot.encoder_resolution)

    def closed_loop(c0: int, c1: int, refs: list, charged: list, log: tuple) -> None:
        """Steps 4–6 for ticks c0 … c1 − 1, appending to the chunk's lists."""
        q_log, _, tau_mpc_log, tau_log, tick_ns, yard_ns = log
        if native_tick is not None:  # encoders, observer, cancellation and plant compiled
            sense, actuate, advance = native_tick.sense, native_tick.actuate, native_tick.advance
            x_hat, u_in, tau, q = native_tick.x, native_tick.u, native_tick.tau, native_tick.q
            for i in range(c0, c1):
                t_start = clock()
                sense()
                ref = refs[i - c0]
                u = controller.step(x_hat, ref)
                u_in[:] = u
                actuate()
                tick_ns.append(clock() - t_start + charged[i - c0])
                if yardstick is not None and i % 16 == 7:
                    t_start = clock()
                    yardstick(x_hat, ref)
                    yard_ns.append(clock() - t_start)
                advance()
                q_log.append(q.tolist())
                tau_mpc_log.append(u.tolist())
                tau_log.append(tau.tolist())
                if progress is not None and (i + 1) % 2000 == 0:
                    progress(i + 1)
            return
        for i in range(c0, c1):
            t_start = clock()
            ref = refs[i - c0]
            q_meas = plant.q
            if resolution is not None:  # encoders: q̃ = Δ·round(q/Δ)
                q_meas = np.multiply(q_meas, inv_resolution, out=encoder)
                np.rint(encoder, out=encoder)
                np.multiply(encoder, resolution, out=encoder)
            x_hat = observer.correct(q_meas)
            u = controller.step(x_hat, ref)
            tau = cancel.torque(q_meas, velocity, u)
            tick_ns.append(clock() - t_start + charged[i - c0])
            if yardstick is not None and i % 16 == 7:
                t_start = clock()
                yardstick(x_hat, ref)
                yard_ns.append(clock() - t_start)
            applied = plant.step(tau)
            # the MPC torque that really acted
            observer.predict(u + (applied - tau) if plant.saturated else u)
            q_log.append(plant.q)
            tau_mpc_log.append(u.tolist())
            tau_log.append(tau.tolist())
            if progress is not None and (i + 1) % 2000 == 0:
                progress(i + 1)

    hold = np.tile(anchor, (N, 1))  # before the first sample: the POI's mean position
    chunk = ds * max(1, chunk_ticks // ds)  # ticks per open-loop pass (a multiple of ds)
    last_j = -1
    clock = time.perf_counter_ns
    pipelined = settings.pipelined_refresh
    if pipelined:  # the first refresh's update, on tick −1 (nothing has arrived yet)
        last_j, _ = _update(reference, cursor, -1, last_j, center, Ts)
    gc_was_enabled = gc.isenabled()
    gc.freeze()  # what exists now is never scanned again …
    gc.disable()  # … and no collection runs inside the 2 kHz loop (a 10-ms stall)
    try:
        for c0 in range(0, n, chunk):
            c1 = min(c0 + chunk, n)
            # Open-loop part: heart → sensor → predictor → reference does not depend on the
            # robot, so a chunk's references are made first, each predictor period timed and
            # charged to its refresh tick; the closed loop then runs with warm caches.
            refs, horizons = [], []
            charged = [0] * (c1 - c0)  # open-loop work [ns] charged to each tick
            for i in range(c0, c1, ds):  # c0 is a multiple of ds: every i refreshes
                spent = 0
                if not pipelined:
                    last_j, spent = _update(reference, cursor, i, last_j, center, Ts)
                t_start = clock()
                reference.forecast()
                # views; later refreshes replace the arrays they view, never change them
                period = reference.horizons(i, min(ds, c1 - i))
                charged[i - c0] += spent + clock() - t_start
                if pipelined and i + ds - 1 < c1:  # the next refresh's update, on its own tick
                    last_j, spent = _update(reference, cursor, i + ds - 1, last_j, center, Ts)
                    charged[i + ds - 1 - c0] += spent
                horizons.append(period[0])  # the refresh's forecast from tick i
                refs.extend(hold if h is None else h for h in period)
            log = record.start_chunk()
            log[1].extend(refs)  # r_{i+1..i+N} of every tick (views)
            closed_loop(c0, c1, refs, charged, log)
            record.end_chunk(c0, c1, log, horizons)
    finally:
        if gc_was_enabled:
            gc.enable()
        gc.unfreeze()
        record.close()

    stats_obj = getattr(controller, "stats", None)
    if dataclasses.is_dataclass(stats_obj):
        stats = dataclasses.asdict(stats_obj)
        stats["fallback_total"] = int(getattr(stats_obj, "fallback_total", 0))
    else:
        stats = dict(stats_obj or {})
    counts = dict(getattr(getattr(reference, "predictor", None), "counts", {}) or {})
    note = f" ({plant.dynamics_note})" if plant.dynamics_note else ""
    return record.result(stats, counts, plant.dynamics + note)


def _update(reference, cursor, tick: int, last_j: int, center, Ts: float) -> tuple[int, int]:
    """Feed the reference the newest sample arrived by ``tick`` (None if none is new).

    Returns the sample's index and the time [ns] of the controller's part. The sensor's delivery
    is not timed: it is the simulated world, which makes the samples a block at a time (≈ 0.4 ms
    per 4096 samples, once every 2 s of a 2-kHz stream).
    """
    j = cursor.newest(tick * Ts + 1e-12)
    new = j >= 0 and j != last_j
    t_j, z_j = cursor.sample(j) if new else (tick * Ts, None)
    t_start = time.perf_counter_ns()
    reference.update(tick, None if z_j is None else z_j - center, t_j)
    return (j if new else last_j), time.perf_counter_ns() - t_start
