"""The closed loop: heart → sensor → predictor → reference → MPC → cancellation → plant.

Time is integer ticks of ``Ts`` (seconds = tick·Ts). Each tick ``i``:

1. the newest sensor sample that has *arrived* by ``i·Ts`` is known (``newest[i]``);
2. every ``downsample`` ticks the reference is refreshed with it (the predictor runs; a tick
   with no new sample since the last refresh is a missing sample for the predictor);
3. the reference gives the N points ``r_{i+1..i+N}``, placed in the robot's workspace:
   ``r = y0 + offset + E·r_c`` (``r_c`` centred heart coordinates);
4. the encoders quantise ``q``, the observer estimates ``x̂ = [q − q0; q̇]``;
5. the MPC computes ``τ_mpc``; the cancellation adds ``ĝ + Ĉq̇ + f̂`` at the estimated state;
6. the plant integrates one tick with the (clipped) torque held.

Steps 1–3 are open-loop — the heart and its sensor do not see the robot — so the loop makes them
for a chunk of ≈ 1 s of ticks ahead (same calls, same order, same results) and then runs steps
4–6 for that chunk. Keeping the two working sets apart saves ≈ 15 µs of a ≈ 90 µs tick;
each predictor period's time is charged to its refresh tick, so the per-tick timing still holds
everything the controller does.

The POI trajectory is centred on its mean over the run and placed at the end-effector's home
position plus ``poi_offset``. A 1-D motion moves along the x axis. The error is
``p_ee(q_{i+1}) − p_poi((i+1)·Ts)``.
"""

from __future__ import annotations

import dataclasses
import gc
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from robots import LinearArm, Robot
from sim.estimation import JointObserver, ObserverSettings
from sim.metrics import rms, timing_stats, tracking_metrics
from sim.plant import ArmPlant, ModelMismatch, NonlinearityCancellation, PlantSettings


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
        one 7.5 ms period); 0 disables [m].
    outlier_max_rejections : int
        After this many consecutive rejected samples the gate opens (a real jump, or a forecast
        gone wrong) until 20 samples in a row fall inside it again [samples].
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
    """

    Ts: float = 0.5e-3
    horizon: int = 50
    downsample: int = 15
    prediction_points: int = 4
    outlier_gate: float = 1.5e-3
    outlier_max_rejections: int = 2
    guard_speed: float = 0.3
    guard_margin: float = 2e-3
    duration: float = 20.0
    settling: float = 5.0
    poi_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

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


def embed3(p: np.ndarray) -> np.ndarray:
    """(n, d) positions with d ≤ 3 as (n, 3), missing axes zero (1-D motion along x)."""
    p = np.atleast_2d(p)
    if p.shape[1] == 3:
        return p
    out = np.zeros((p.shape[0], 3))
    out[:, : p.shape[1]] = p
    return out


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


@dataclass
class LoopResult:
    """What a run produced (SI units); :meth:`metrics` summarises it."""

    settings: LoopSettings
    time: np.ndarray  # (n,) [s], the instant of each recorded state (i+1)·Ts
    ee: np.ndarray  # (n, 3) end-effector position [m]
    poi: np.ndarray  # (n, 3) true POI position [m]
    reference0: np.ndarray  # (n, 3) first reference point r_{i+1} given to the MPC [m]
    tau_mpc: np.ndarray  # (n, nv) [N·m]
    tau: np.ndarray  # (n, nv) applied torque after clipping [N·m]
    tick_ns: np.ndarray  # (n,) controller time per tick [ns]
    horizon_error: np.ndarray  # (N,) RMS error of the reference vs the truth per lead tick [m]
    controller_stats: dict = field(default_factory=dict)
    saturated_ticks: int = 0
    predictor_counts: dict = field(default_factory=dict)

    @property
    def error(self) -> np.ndarray:
        return self.ee - self.poi

    def metrics(self) -> dict:
        s = self.settings.settling_ticks
        out = tracking_metrics(self.error[s:], self.tau_mpc[s:], self.tau[s:])
        out["tick_us"] = timing_stats(self.tick_ns[s:])
        out["prediction_rms_mm"] = {
            "lead_1": float(1e3 * self.horizon_error[0]),
            "lead_N": float(1e3 * self.horizon_error[-1]),
            "mean": float(1e3 * rms(self.horizon_error)),
        }
        out["saturated_ticks"] = int(self.saturated_ticks)
        return out


def run_closed_loop(
    robot: Robot,
    arm: LinearArm,
    controller,
    reference,
    truth: np.ndarray,
    center: np.ndarray,
    stream,
    settings: LoopSettings,
    *,
    plant_settings: PlantSettings | None = None,
    mismatch: ModelMismatch | None = None,
    observer_settings: ObserverSettings | None = None,
    progress: Callable[[int], None] | None = None,
) -> LoopResult:
    """Run the closed loop for ``settings.duration``.

    Parameters
    ----------
    controller
        ``step(x, ref) -> τ_mpc`` and a ``stats`` mapping
        (:class:`rhmpc.control.mpc.RecedingHorizonMPC`).
    reference
        ``place(origin)``, ``refresh(tick, z, stamp)`` and ``horizons(tick, count)`` → the
        (N, 3) points of ticks tick … tick + count − 1, None before the first sample
        (:mod:`rhmpc.control.reference`); the loop places it at the workspace anchor before the run.
    truth, center
        From :func:`poi_truth` over at least ``ticks + horizon + 1`` ticks.
    stream
        Sensor samples with arrays ``t`` [s], ``z`` (n, d) [m] (NaN = missing) and ``arrival`` [s].
    progress
        Called with the number of ticks done, every 2000 ticks.
    """
    n, N, ds, Ts = settings.ticks, settings.horizon, settings.downsample, settings.Ts
    if truth.shape[0] < n + N + 1:
        raise ValueError(f"truth covers {truth.shape[0]} ticks, the run needs {n + N + 1}")
    anchor = arm.y0 + np.asarray(settings.poi_offset, dtype=float)
    poi = anchor + embed3(truth[1 : n + 1])

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
    newest = newest_arrived(np.asarray(stream.arrival, dtype=float), n, Ts)
    z_all = np.asarray(stream.z, dtype=float).reshape(len(stream.t), -1) - center
    t_all = np.asarray(stream.t, dtype=float)

    # Per-tick logs as lists of floats (an append is cheaper than a row store); arrays after.
    q_log: list = []  # plant.q: the plant replaces its arrays, never mutates them
    ref0: list = []
    tau_mpc_log: list = []
    tau_log: list = []  # commanded: τ_mpc + cancellation, before the actuator clip
    tick_ns: list = []
    n_updates = (n + ds - 1) // ds
    horizons = np.full((n_updates, N, 3), np.nan)  # workspace points
    hold = np.tile(anchor, (N, 1))  # before the first sample: the POI's mean position
    chunk = ds * max(1, 2000 // ds)  # ticks per open-loop pass (a multiple of ds, ≈ 1 s)
    last_j = -1
    clock = time.perf_counter_ns
    gc_was_enabled = gc.isenabled()
    gc.disable()  # a collection inside the 2 kHz loop would be a 10-ms stall
    try:
        for c0 in range(0, n, chunk):
            c1 = min(c0 + chunk, n)
            # Open-loop part: heart → sensor → predictor → reference does not depend on the
            # robot, so a chunk's references are made first, each predictor period timed and
            # charged to its refresh tick; the closed loop then runs with warm caches.
            refs, period_ns = [], []
            for i in range(c0, c1, ds):  # c0 is a multiple of ds: every i refreshes
                t_start = clock()
                j = newest[i]
                if j >= 0 and j != last_j:
                    last_j = j
                    reference.refresh(i, z_all[j], t_all[j])
                else:
                    reference.refresh(i, None, i * Ts)
                # views; later refreshes replace the arrays they view, never change them
                period = reference.horizons(i, min(ds, c1 - i))
                if period[0] is not None:
                    horizons[i // ds] = period[0]
                refs.extend(hold if h is None else h for h in period)
                period_ns.append(clock() - t_start)
            for i in range(c0, c1):
                t_start = clock()
                ref = refs[i - c0]
                q_meas = plant.q
                if resolution is not None:  # encoders: q̃ = Δ·round(q/Δ)
                    q_meas = np.multiply(q_meas, inv_resolution, out=encoder)
                    np.rint(encoder, out=encoder)
                    encoder *= resolution
                x_hat = observer.correct(q_meas)
                u = controller.step(x_hat, ref)
                tau = cancel.torque(q_meas, velocity, u)
                elapsed = clock() - t_start
                tick_ns.append(elapsed + period_ns[(i - c0) // ds] if i % ds == 0 else elapsed)
                applied = plant.step(tau)
                # the MPC torque that really acted
                observer.predict(u + (applied - tau) if plant.saturated else u)
                q_log.append(plant.q)
                ref0.append(ref[0].tolist())
                tau_mpc_log.append(u.tolist())
                tau_log.append(tau.tolist())
                if progress is not None and (i + 1) % 2000 == 0:
                    progress(i + 1)
    finally:
        if gc_was_enabled:
            gc.enable()

    q_log, ref0 = np.array(q_log), np.array(ref0)
    tau_mpc_log, tau_log = np.array(tau_mpc_log), np.array(tau_log)
    tick_ns = np.array(tick_ns, dtype=np.int64)
    limit = robot.torque_limit
    saturated = np.abs(tau_log) > limit
    saturated_ticks = int(saturated.any(axis=1).sum())
    tau_log = np.clip(tau_log, -limit, limit)  # what acted
    model, data, fid = robot.model, robot.create_data(), robot.ee_frame_id
    ee = []
    for q in q_log:
        pin.forwardKinematics(model, data, q)
        ee.append(pin.updateFramePlacement(model, data, fid).translation)
    ee = np.array(ee).reshape(n, 3)
    # Horizon prediction error per lead tick, after settling.
    first = -(-settings.settling_ticks // ds)
    lead = np.arange(1, N + 1)
    placed_truth = anchor + embed3(truth)
    err = []
    for k in range(first, n_updates):
        tick = k * ds
        if tick + N < truth.shape[0] and np.all(np.isfinite(horizons[k])):
            err.append(np.linalg.norm(horizons[k] - placed_truth[tick + lead], axis=1))
    horizon_error = rms(np.array(err), axis=0) if err else np.full(N, np.nan)

    stats_obj = getattr(controller, "stats", None)
    if dataclasses.is_dataclass(stats_obj):
        stats = dataclasses.asdict(stats_obj)
        stats["fallback_total"] = int(getattr(stats_obj, "fallback_total", 0))
    else:
        stats = dict(stats_obj or {})
    counts = dict(getattr(getattr(reference, "predictor", None), "counts", {}) or {})
    return LoopResult(
        settings=settings,
        time=(np.arange(n) + 1) * Ts,
        ee=ee,
        poi=poi,
        reference0=ref0,
        tau_mpc=tau_mpc_log,
        tau=tau_log,
        tick_ns=tick_ns,
        horizon_error=horizon_error,
        controller_stats=stats,
        saturated_ticks=saturated_ticks,
        predictor_counts=counts,
    )
