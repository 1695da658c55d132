"""What a closed-loop run leaves: running statistics, a fixed-size trace, the trace file.

:class:`Recorder` takes each chunk of ticks from :func:`sim.loop.run_closed_loop` (joint angles,
references, torques, tick times), turns it into running statistics (:mod:`sim.loop.metrics`), the
decimated trace and the optional trace file (:mod:`sim.loop.trace`), and forgets it; memory does not
grow with the run. :class:`LoopResult` is what the run returns.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from robots import Robot
from sim.loop.metrics import RunningTracking, TickHistogram, rms
from sim.loop.trace import DecimatedTrace, TraceFile

#: The parts of a refresh charged to the ticks that run them: the predictor's update with the
#: outlier gate, its learning (where it defers it), its forecast, the interpolation with the
#: guard and placement, and the forecast-error bookkeeping (``Predictor.score``).
CHARGED = ("predictor_update", "predictor_learn", "forecast", "interpolation", "scoring")
#: The parts of a control tick, timed separately: the encoders and the observer, the
#: controller, the cancellation (the commanded torque), and the refresh slices (CHARGED).
TICK_PARTS = ("sense", "controller", "actuate", *CHARGED)
#: The yardstick is timed on the ticks i ≡ YARDSTICK_PHASE (mod YARDSTICK_EVERY)
#: (``run_closed_loop(yardstick=…)``): 1 875 samples for its p50 in a simulated minute, whose
#: three calls each add ≈ 0.1 µs a tick to the run's wall time.
YARDSTICK_EVERY, YARDSTICK_PHASE = 64, 7


def embed3(p: np.ndarray) -> np.ndarray:
    """(n, d) positions with d ≤ 3 as (n, 3), missing axes zero (1-D motion along x)."""
    if getattr(p, "ndim", 0) == 2 and p.shape[1] == 3:  # already (n, 3): the array, at once
        return p
    p = np.atleast_2d(p)
    if p.shape[1] == 3:
        return p
    out = np.zeros((p.shape[0], 3))
    out[:, : p.shape[1]] = p
    return out


@dataclass
class LoopResult:
    """What a run produced: its metrics, and a fixed-size trace of its ticks (SI units).

    The per-tick arrays (``time``, ``ee``, ``poi``, ``reference0``, ``tau_mpc``, ``tau``,
    ``tick_ns``) are those of the decimated trace (:class:`sim.loop.trace.DecimatedTrace`:
    every tick of a run up to 20 000 ticks long; beyond, every ``stride``-th tick plus the last
    2 s at full rate). The metrics cover every tick after settling.
    """

    settings: object  # sim.loop.LoopSettings
    trace: dict  # field -> array over the traced ticks
    stride: int  # ticks between traced samples before the full-rate tail
    tracking: dict  # tracking_metrics of every tick after settling
    tick_us: dict  # p50 / p99 / p999 / max / mean of the whole control tick [µs]
    yardstick_us: dict  # the same of the yardstick (gain tick) timed in the run [µs]
    tick_parts_us: dict  # the same per part of the tick (TICK_PARTS) [µs]
    #: the same of the tick without the refresh slices (sense + controller + actuate) [µs]:
    #: what it would cost with the predictor in a task of its own
    control_tick_us: dict
    horizon_error: np.ndarray  # (N,) RMS error of the reference vs the truth per lead tick [m]
    controller_stats: dict = field(default_factory=dict)
    saturated_ticks: int = 0
    predictor_counts: dict = field(default_factory=dict)
    plant_dynamics: str = "pinocchio"  # who integrated the plant (and why not native)
    #: who ran the control ticks: "compiled" (C, between the refresh slices), or "python (why)"
    tick_loop: str = "python"

    time = property(lambda self: self.trace["time"])  # [s], the instant of the state (i+1)·Ts
    ee = property(lambda self: self.trace["ee"])  # (n, 3) end-effector position [m]
    poi = property(lambda self: self.trace["poi"])  # (n, 3) true POI position [m]
    reference0 = property(lambda self: self.trace["reference0"])  # (n, 3) r_{i+1} [m]
    tau_mpc = property(lambda self: self.trace["tau_mpc"])  # (n, nv) [N·m]
    tau_command = property(lambda self: self.trace["tau_command"])  # (n, nv) before the clip
    tau = property(lambda self: self.trace["tau"])  # (n, nv) applied, after the clip [N·m]
    tick_ns = property(lambda self: self.trace["tick_ns"])  # (n,) whole control tick [ns]

    @property
    def error(self) -> np.ndarray:
        return self.ee - self.poi

    def metrics(self) -> dict:
        out = dict(self.tracking)
        out["tick_us"] = dict(self.tick_us)
        out["tick_parts_us"] = {k: dict(v) for k, v in self.tick_parts_us.items()}
        out["control_tick_us"] = dict(self.control_tick_us)
        out["prediction_rms_mm"] = {
            "lead_1": float(1e3 * self.horizon_error[0]),
            "lead_N": float(1e3 * self.horizon_error[-1]),
            "mean": float(1e3 * rms(self.horizon_error)),
        }
        out["saturated_ticks"] = int(self.saturated_ticks)
        return out


class Recorder:
    """Turns each chunk's per-tick lists into running statistics, the trace and the trace file."""

    def __init__(self, robot: Robot, settings, truth, anchor, trace_file) -> None:
        self.robot, self.settings, self.truth, self.anchor = robot, settings, truth, anchor
        self.model, self.data, self.fid = robot.model, robot.create_data(), robot.ee_frame_id
        from sim.plant.native import load_chain

        # end-effector positions of a whole chunk in one compiled call (else Pinocchio per tick)
        self.chain = load_chain(robot.model)
        frame = robot.model.frames[self.fid]
        self.ee_joint, self.ee_point = frame.parentJoint, np.array(frame.placement.translation)
        self.tracking = RunningTracking()
        self.ticks = TickHistogram()
        self.yardstick = TickHistogram()
        self.parts = {name: TickHistogram() for name in TICK_PARTS}
        self.control = TickHistogram()  # sense + controller + actuate
        self.trace = DecimatedTrace(settings.ticks)
        self.file = None if trace_file is None else TraceFile(trace_file)
        N = settings.horizon
        self.lead = np.arange(1, N + 1)
        self.horizon2, self.n_horizons = np.zeros(N), np.zeros(N, dtype=np.int64)
        self.saturated_ticks = 0

    def start_chunk(self, m: int, charged: tuple[list[int], ...],
                    u_prev: np.ndarray | None) -> dict:
        """The records of a chunk of ``m`` ticks, preallocated (the loop writes rows, allocates
        nothing): q, τ_mpc and the commanded τ (m, nv), the tick's parts [ns] (m, 3), the first
        reference point (m, 3), x̂ where the yardstick needs it (compiled ticks), the yardstick
        [ns]; the refresh slices' ns per part (:data:`CHARGED`), written as they run; u_{−1}
        carried from the last chunk."""
        nq, nv = self.robot.nq, self.robot.nv
        return {"q": np.empty((m, nq)), "ref0": np.empty((m, 3)), "tau_mpc": np.empty((m, nv)),
                "tau": np.empty((m, nv)), "parts_ns": np.empty((m, 3), dtype=np.int64),
                "x_saved": np.empty((m // YARDSTICK_EVERY + 1, 2 * nv)), "yardstick_ns": [],
                "charged": charged, "u_prev": u_prev}

    def end_chunk(self, c0: int, c1: int, log, horizons: list) -> None:
        settings, N = self.settings, self.settings.horizon
        q_log, ref0, tau_mpc, tau_cmd = log["q"], log["ref0"], log["tau_mpc"], log["tau"]
        parts = log["parts_ns"]
        charged = np.array(log["charged"], dtype=np.int64)  # (parts, m)
        tick_ns = parts.sum(axis=1) + charged.sum(axis=0)  # the control tick and its slices
        self.yardstick.add(np.array(log["yardstick_ns"], dtype=np.int64))
        m = c1 - c0
        if self.chain is not None:
            ee = self.chain.points(q_log, self.ee_joint, self.ee_point)
        else:
            model, data, fid = self.model, self.data, self.fid
            ee = np.empty((m, 3))
            for k, q in enumerate(q_log):
                pin.forwardKinematics(model, data, q)
                ee[k] = pin.updateFramePlacement(model, data, fid).translation
        placed = self.anchor + embed3(self.truth.window(c0, c1 + N + 1))
        poi = placed[1 : m + 1]
        limit = self.robot.torque_limit
        self.saturated_ticks += int((np.abs(tau_cmd) > limit).any(axis=1).sum())
        tau = np.clip(tau_cmd, -limit, limit)  # what acted
        s = max(settings.settling_ticks - c0, 0)
        self.tracking.add(ee[s:] - poi[s:], tau_mpc[s:], tau[s:])
        self.ticks.add(tick_ns[s:])
        for k, name in enumerate(("sense", "controller", "actuate")):
            self.parts[name].add(parts[s:, k])
        self.control.add(parts[s:].sum(axis=1))
        for row, name in zip(charged, CHARGED, strict=True):
            self.parts[name].add(row[s:])
        self._horizon_errors(c0, horizons, placed)
        ticks = np.arange(c0, c1)
        chunk = {"tick": ticks, "time": (ticks + 1) * settings.Ts, "ee": ee, "poi": poi,
                 "reference0": ref0, "tau_mpc": tau_mpc,
                 "tau_command": tau_cmd,
                 "tau": tau, "tick_ns": tick_ns}
        self.trace.add(chunk)
        if self.file is not None:
            self.file.add(chunk)

    def _horizon_errors(self, c0: int, horizons: list, placed: np.ndarray) -> None:
        """Add the squared miss of each refresh's N points (after settling) to the running sum
        per lead tick; a refresh with a non-finite point is left out, a lead without truth is
        skipped for that refresh alone."""
        N, settling = self.settings.horizon, self.settings.settling_ticks
        kept = [(tick, h) for tick, h in horizons
                if tick >= settling and h is not None and tick + N < self.truth.n_ticks]
        if not kept:
            return
        points = np.array([h for _, h in kept])  # (refreshes, N, 3)
        finite_points = np.isfinite(points).all(axis=(1, 2))
        ticks = np.array([tick for tick, _ in kept])[finite_points]
        err2 = np.square(points[finite_points] - placed[ticks[:, None] - c0 + self.lead]).sum(
            axis=2)
        finite = np.isfinite(err2)  # no truth at some leads: skipped per lead
        # in order, refresh after refresh (a running sum, as np.add.accumulate makes it)
        rows = np.vstack((self.horizon2, np.where(finite, err2, 0.0)))
        self.horizon2 = np.add.accumulate(rows, axis=0)[-1]
        self.n_horizons += finite.sum(axis=0)

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None

    def result(self, stats: dict, counts: dict, dynamics: str = "pinocchio",
               loop: str = "python") -> LoopResult:
        with np.errstate(invalid="ignore", divide="ignore"):
            horizon_error = np.sqrt(self.horizon2 / self.n_horizons)  # NaN where no refresh
        return LoopResult(
            settings=self.settings, trace=self.trace.arrays(), stride=self.trace.stride,
            tracking=self.tracking.result(), tick_us=self.ticks.stats_us(),
            yardstick_us=self.yardstick.stats_us(),
            tick_parts_us={name: h.stats_us() for name, h in self.parts.items()},
            control_tick_us=self.control.stats_us(), horizon_error=horizon_error,
            controller_stats=stats,
            saturated_ticks=self.saturated_ticks, predictor_counts=counts,
            plant_dynamics=dynamics, tick_loop=loop,
        )
