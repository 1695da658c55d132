"""What a closed-loop run leaves: running statistics, a fixed-size trace, the trace file.

:class:`Recorder` takes each chunk of ticks from :func:`rhmpc.sim.loop.run_closed_loop` (joint
angles, references, torques, tick times), turns it into running statistics
(:mod:`rhmpc.sim.loop.metrics`), the decimated trace and the optional trace file
(:mod:`rhmpc.sim.loop.trace`), and forgets it; memory does not grow with the run.
:class:`LoopResult` is what the run returns.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from rhmpc.positions import embed3
from rhmpc.robots import Robot
from rhmpc.sim.loop.metrics import MeasuredScore, RunningTracking, TickHistogram, rms
from rhmpc.sim.loop.trace import DecimatedTrace, TraceFile

#: The parts of a tick, timed separately: the controller's step (observer, MPC, cancellation)
#: and the refreshes of its reference on that tick (gate, predictor, interpolation).
TICK_PARTS = ("step", "refresh")
#: The yardstick is timed on the ticks i ≡ YARDSTICK_PHASE (mod YARDSTICK_EVERY)
#: (``run_closed_loop(yardstick=…)``): 1 875 samples for its p50 in a simulated minute.
YARDSTICK_EVERY, YARDSTICK_PHASE = 64, 7
#: The most refreshes (and their samples) a result keeps for figures.
KEPT_REFRESHES = 4000
#: Samples measured this long before a chunk's start are scored at its end [s]: by then the
#: controller has judged them (its gate, and a retraction one sample period later).
JUDGED_AFTER_S = 1.0
#: What a run's ``rms_error_mm`` compares, by its truth: a recording's samples at their own
#: instants, or a synthetic motion known at every tick.
SCORES = {"measured": "the tool against each recorded sample, at the sample's instant",
          "continuous": "the tool against the true motion, at every tick"}


@dataclass
class LoopResult:
    """What a run produced: its metrics, and a fixed-size trace of its ticks (SI units).

    The per-tick arrays (``time``, ``ee``, ``poi``, ``reference0``, ``tau_mpc``, ``tau``,
    ``tick_ns``, and ``trace["q"]``) are those of the decimated trace
    (:class:`rhmpc.sim.loop.trace.DecimatedTrace`: every tick of a run up to 20 000 ticks long;
    beyond, every ``stride``-th tick plus the last 2 s at full rate). ``horizons`` holds the N
    points each refresh made (ticks (R,), points (R, N, 3) [m]) and ``samples`` the sensor samples
    that refreshed them, placed in the workspace (t (S,) [s], z (S, 3) [m], NaN for a missing
    one), each of at most :data:`KEPT_REFRESHES` evenly spread refreshes. The metrics cover
    the run after settling: every tick of a continuous truth, or a recording's samples at their
    own instants (:attr:`score`).
    """

    settings: object  # rhmpc.sim.loop.LoopSettings
    trace: dict  # field -> array over the traced ticks
    stride: int  # ticks between traced samples before the full-rate tail
    #: the tracking metrics after settling: at every tick against the truth, or with
    #: ``measured`` at the recorded samples' instants
    #: (:class:`~rhmpc.sim.loop.metrics.MeasuredScore`; the all-tick score against the samples'
    #: interpolant then in ``interpolated``)
    tracking: dict
    tick_us: dict  # p50 / p99 / p999 / max / mean of the whole control tick [µs]
    yardstick_us: dict  # the same of the yardstick (gain tick) timed in the run [µs]
    tick_parts_us: dict  # the same per part of the tick (TICK_PARTS) [µs]
    #: the same of the tick without the refreshes (the step alone) [µs]: what it would cost
    #: with the predictor in a task of its own
    control_tick_us: dict
    #: each refresh's time [µs] (p50 … max, ``over_period``: refreshes longer than the
    #: predictor's period, which a predictor in a task of its own could not keep up with)
    refresh_us: dict
    horizon_error: np.ndarray  # (N,) RMS error of the reference vs the truth per lead tick [m]
    controller_stats: dict = field(default_factory=dict)
    saturated_ticks: int = 0
    predictor_counts: dict = field(default_factory=dict)
    #: what the score leaves out: the samples taken as outliers, the ticks whose truth touches
    #: them, and the recorded samples that are no measurements (their truth is missing)
    excluded: dict = field(default_factory=dict)
    horizons: tuple = (np.zeros(0, dtype=np.int64), np.zeros((0, 0, 3)))
    samples: tuple = (np.zeros(0), np.zeros((0, 3)))
    #: the plant's joint angles against the robot's joint limits over the whole run
    #: (:class:`JointEnvelope`): ``position_margin_rad``, ``speed_margin_rad_s``, ``held``
    envelope: dict = field(default_factory=dict)
    #: with ``run_closed_loop(marks=…)``, one record per stretch of ticks between marks
    #: (:meth:`Recorder.count`): ``ticks`` (i0, i1), ``max_error_m`` (every tick, settling
    #: included; NaN without truth), ``envelope`` and the event ``counts`` at its end
    segments: tuple = ()
    #: with a recording: the all-tick score against its linear interpolant, keys suffixed
    #: ``_interpolated`` (``rms_error_interpolated_mm`` …); empty for a continuous truth
    interpolated: dict = field(default_factory=dict)
    #: with a recording: its samples (t (n,) [s], p (n, 3) [m] placed in the workspace, and
    #: whether each is in the score), the truth of :attr:`score` ``"measured"``
    measured: tuple = ()

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

    @property
    def score(self) -> str:
        """``"measured"`` (a recording's samples) or ``"continuous"`` (:data:`SCORES`)."""
        return "measured" if self.interpolated else "continuous"

    def metrics(self) -> dict:
        out = dict(self.tracking)
        out["score"] = self.score
        out["score_description"] = SCORES[self.score]
        out.update(self.interpolated)
        out["tick_us"] = dict(self.tick_us)
        out["tick_parts_us"] = {k: dict(v) for k, v in self.tick_parts_us.items()}
        out["control_tick_us"] = dict(self.control_tick_us)
        out["refresh_us"] = dict(self.refresh_us)
        out["prediction_rms_mm"] = {
            "lead_1": float(1e3 * self.horizon_error[0]),
            "lead_N": float(1e3 * self.horizon_error[-1]),
            "mean": float(1e3 * rms(self.horizon_error)),
        }
        out["saturated_ticks"] = int(self.saturated_ticks)
        out["excluded"] = dict(self.excluded)
        out["joint_envelope"] = dict(self.envelope)
        return out


class JointEnvelope:
    """The plant's joint angles against the robot's joint limits, chunk by chunk.

    The position margin is the least of q − q_lower, q_upper − q and, for each coupled limit
    lo ≤ c·q ≤ hi (:attr:`rhmpc.robots.Robot.coupling`), c·q − lo and hi − c·q [rad]; the speed
    margin is the least of v_max − abs(q_{i+1} − q_i) / Ts, the mean speed over each tick [rad/s].
    The envelope *held* when both stay ≥ 0 (the limits the MPC's envelope enforces by default,
    :mod:`rhmpc.control.envelope`).
    """

    def __init__(self, robot: Robot, Ts: float) -> None:
        self.lower, self.upper = robot.position_limits
        self.coupling, self.vmax, self.Ts = robot.coupling, robot.velocity_limit, Ts
        self.q_prev: np.ndarray | None = None
        self.position, self.speed = np.inf, np.inf

    def margins(self, q: np.ndarray) -> tuple[float, float]:
        """(position [rad], speed [rad/s]) margins of the joint angles ``q`` (m, nq) that
        follow the last chunk's; both also folded into the run's."""
        gaps = [q - self.lower, self.upper - q]
        for c, lo, hi in self.coupling:
            cq = q @ c
            gaps += [(cq - lo)[:, None], (hi - cq)[:, None]]
        position = float(min(g.min() for g in gaps)) if q.size else np.inf
        path = q if self.q_prev is None else np.vstack([self.q_prev, q])
        speed = np.abs(np.diff(path, axis=0)) / self.Ts
        speed = float((self.vmax - speed).min()) if speed.size else np.inf
        self.q_prev = q[-1] if q.size else self.q_prev
        self.position, self.speed = min(self.position, position), min(self.speed, speed)
        return position, speed

    @staticmethod
    def document(position: float, speed: float) -> dict:
        """``position_margin_rad``, ``speed_margin_rad_s`` and ``held`` (both ≥ 0)."""
        return {"position_margin_rad": position, "speed_margin_rad_s": speed,
                "held": bool(position >= 0 and speed >= 0)}

    def result(self) -> dict:
        return self.document(self.position, self.speed)


class Recorder:
    """Turns each chunk's per-tick records into running statistics, the trace and the trace file."""

    def __init__(self, robot: Robot, settings, horizon: int, truth, anchor, trace_file,
                 clock, segmented: bool = False, measured: tuple | None = None) -> None:
        self.robot, self.settings, self.N = robot, settings, horizon
        self.truth, self.anchor = truth, np.asarray(anchor, dtype=float)
        self.model, self.data, self.fid = robot.model, robot.create_data(), robot.ee_frame_id
        self.tracking = RunningTracking()
        #: a recording's samples (t [s], z (n, d) [m], uncentred): scored at their instants
        self.measured = None if measured is None else self._measured_score(*measured)
        self.after_last_ticks = 0  # ticks after a recording's last sample: not scored
        self.ticks = TickHistogram()
        self.yardstick = TickHistogram()
        self.parts = {name: TickHistogram() for name in TICK_PARTS}
        #: each refresh against the predictor's period: up to 100 ms in 1-µs bins (0.8 MB)
        self.refreshes = TickHistogram(resolution_ns=1000, span_ns=100_000_000)
        self.period_ns = 1e9 * clock.dt
        self.trace = DecimatedTrace(settings.ticks)
        self.file = None if trace_file is None else TraceFile(trace_file)
        self.lead = np.arange(1, horizon + 1)
        self.horizon2, self.n_horizons = np.zeros(horizon), np.zeros(horizon, dtype=np.int64)
        self.saturated_ticks = 0
        expected = settings.duration / clock.dt + 1  # refreshes of the run
        self.keep_every = max(1, int(np.ceil(expected / KEPT_REFRESHES)))
        self.n_refreshes = 0
        self.kept_horizons: list = []
        self.kept_samples: list = []
        self.u_prev, self.last_stamp = None, None
        #: stamps of the samples the controller took as outliers [s], and the half-width of
        #: the truth they touch: one raw sample period each side (the truth interpolates them)
        self.outliers: list[float] = []
        self.reach = 1.0 / clock.sensor_rate if np.isfinite(clock.sensor_rate) else clock.dt
        self.excluded_ticks = 0
        self.envelope = JointEnvelope(robot, settings.Ts)
        #: per chunk, with ``segmented``: its ticks, max error and envelope (then its counts)
        self.segments: list[dict] | None = [] if segmented else None

    def _measured_score(self, t: np.ndarray, z: np.ndarray) -> MeasuredScore:
        """The score at the samples ``z`` (n, d) [m] measured at ``t`` [s], placed as the truth
        is (its centre off, at the anchor), from the settling's end to the run's."""
        z = np.asarray(z, dtype=float).reshape(np.size(t), -1)
        placed = self.anchor + embed3(z - self.truth.center)
        s = self.settings
        return MeasuredScore(t, placed, s.settling_ticks * s.Ts, s.ticks * s.Ts, s.Ts)

    def start_chunk(self, c0: int, c1: int) -> dict:
        """The records of ticks c0 … c1 − 1, preallocated (the loop writes rows): q (m, nq), the
        first reference point (m, 3), τ_mpc, the applied and the commanded τ (m, nv), the step's
        and the refreshes' ns (m,); each refresh's ``(tick, points)`` and ``(stamp, z)``; the
        yardstick [ns]; u_{−1} carried from the last chunk."""
        m, nq, nv = c1 - c0, self.robot.nq, self.robot.nv
        return {"q": np.empty((m, nq)), "ref0": np.empty((m, 3)), "u": np.empty((m, nv)),
                "tau": np.empty((m, nv)), "cmd": np.empty((m, nv)),
                "step_ns": np.zeros(m, dtype=np.int64), "refresh_ns": np.zeros(m, dtype=np.int64),
                "horizons": [], "samples": [], "yardstick_ns": [], "refresh_each_ns": [],
                "u_prev": self.u_prev,
                "outliers": self.outliers, "last_stamp": self.last_stamp}

    def _ee(self, q_log: np.ndarray) -> np.ndarray:
        """End-effector positions (m, 3) of the joint angles (m, nq) (Pinocchio)."""
        model, data, fid = self.model, self.data, self.fid
        ee = np.empty((q_log.shape[0], 3))
        for k, q in enumerate(q_log):
            pin.forwardKinematics(model, data, q)
            ee[k] = pin.updateFramePlacement(model, data, fid).translation
        return ee

    def end_chunk(self, c0: int, c1: int, log: dict) -> None:
        """Fold the chunk's records into the statistics, the trace and the trace file."""
        self.u_prev, self.last_stamp = log["u_prev"], log["last_stamp"]
        m, N = c1 - c0, self.N
        ee = self._ee(log["q"])
        placed = self.anchor + embed3(self.truth.window(c0, c1 + N + 1))
        poi = placed[1 : m + 1]
        scored = self._without_outliers(c0, poi)
        limit = self.robot.torque_limit
        self.saturated_ticks += int((np.abs(log["cmd"]) > limit).any(axis=1).sum())
        s = max(self.settings.settling_ticks - c0, 0)
        tick_ns = log["step_ns"] + log["refresh_ns"]
        if self.measured is not None:
            self.measured.add(c0, ee)
            self.measured.fold(self.outliers, c0 * self.settings.Ts - JUDGED_AFTER_S)
            scored = self._before_last_sample(c0, scored, s)
        self.tracking.add(ee[s:] - scored[s:], log["u"][s:], log["tau"][s:])
        self.ticks.add(tick_ns[s:])
        self.parts["step"].add(log["step_ns"][s:])
        self.parts["refresh"].add(log["refresh_ns"][s:])
        self.yardstick.add(np.array(log["yardstick_ns"], dtype=np.int64))
        self.refreshes.add(np.array(log["refresh_each_ns"], dtype=np.int64))
        self._horizon_errors(c0, log["horizons"], placed)
        self._segment(c0, c1, ee - poi, log["q"])
        self._keep_refreshes(log["horizons"], log["samples"])
        ticks = np.arange(c0, c1)
        chunk = {"tick": ticks, "time": (ticks + 1) * self.settings.Ts, "ee": ee, "poi": poi,
                 "reference0": log["ref0"], "tau_mpc": log["u"], "tau_command": log["cmd"],
                 "tau": log["tau"], "tick_ns": tick_ns, "q": log["q"]}
        self.trace.add(chunk, None if self.measured is None else self.measured.rows(c0, m))
        if self.file is not None:
            self.file.add(chunk)

    def _segment(self, c0: int, c1: int, error: np.ndarray, q: np.ndarray) -> None:
        """The chunk's envelope margins, and with ``segmented`` its record: every tick's
        largest ‖p_ee − p_poi‖ [m] (NaN if no tick has truth) and its margins."""
        margins = self.envelope.margins(q)
        if self.segments is None:
            return
        norm = np.linalg.norm(error, axis=1)
        finite = norm[np.isfinite(norm)]
        self.segments.append({"ticks": (c0, c1),
                              "max_error_m": float(finite.max()) if finite.size else np.nan,
                              "envelope": JointEnvelope.document(*margins)})

    def count(self, counts: dict) -> None:
        """The event counts at the end of the last chunk (with ``segmented``)."""
        self.segments[-1]["counts"] = dict(counts, saturated_ticks=self.saturated_ticks)

    def _without_outliers(self, c0: int, poi: np.ndarray) -> np.ndarray:
        """``poi`` with NaN on the ticks whose recorded truth touches a sample the controller
        took as an outlier (within one raw sample period of it): no score against them."""
        if not self.outliers:
            return poi
        times = (c0 + 1 + np.arange(poi.shape[0])) * self.settings.Ts
        stamps = np.asarray(self.outliers)
        near = np.abs(times[:, None] - stamps[None, :]).min(axis=1) < self.reach
        if not near.any():
            return poi
        settled = c0 + 1 + np.arange(poi.shape[0]) > self.settings.settling_ticks
        self.excluded_ticks += int((near & settled).sum())
        poi = poi.copy()
        poi[near] = np.nan
        return poi

    def _before_last_sample(self, c0: int, poi: np.ndarray, s: int) -> np.ndarray:
        """``poi`` with NaN on the ticks after the recording's last sample (counted after
        settling): nobody measured the heart there."""
        times = (c0 + 1 + np.arange(poi.shape[0])) * self.settings.Ts
        after = times > self.measured.last + 1e-9
        if not after.any():
            return poi
        self.after_last_ticks += int(after[s:].sum())
        poi = poi.copy()
        poi[after] = np.nan
        return poi

    def _keep_refreshes(self, horizons: list, samples: list) -> None:
        """Every ``keep_every``-th refresh's points and sample, for the figures: the sample
        placed as the truth is (its centre off, at the anchor), where it was measured."""
        start, every = self.n_refreshes, self.keep_every
        for k, (horizon, sample) in enumerate(zip(horizons, samples, strict=False)):
            if (start + k) % every == 0:
                self.kept_horizons.append(horizon)
                stamp, z = sample
                z = (np.full(3, np.nan) if z is None
                     else self.anchor + embed3(np.asarray(z) - self.truth.center)[0])
                self.kept_samples.append((stamp, z))
        self.n_refreshes += len(horizons)

    def _horizon_errors(self, c0: int, horizons: list, placed: np.ndarray) -> None:
        """Add the squared miss of each refresh's N points (after settling) to the running sum
        per lead tick; a refresh with a non-finite point is left out, a lead without truth is
        skipped for that refresh alone."""
        N, settling = self.N, self.settings.settling_ticks
        kept = [(tick, h) for tick, h in horizons
                if tick >= settling and tick + N < self.truth.n_ticks]
        if not kept:
            return
        points = np.array([h for _, h in kept])  # (refreshes, N, 3)
        finite_points = np.isfinite(points).all(axis=(1, 2))
        ticks = np.array([tick for tick, _ in kept])[finite_points]
        err2 = np.square(points[finite_points] - placed[ticks[:, None] - c0 + self.lead]).sum(
            axis=2)
        finite = np.isfinite(err2)  # no truth at some leads: skipped per lead
        self.horizon2 += np.where(finite, err2, 0.0).sum(axis=0)
        self.n_horizons += finite.sum(axis=0)

    def close(self) -> None:
        if self.file is not None:
            self.file.close()
            self.file = None

    def _scores(self) -> tuple[dict, dict, dict]:
        """(tracking, interpolated, excluded): with a recording, the score at its samples'
        instants and the all-tick one renamed; else the all-tick score alone."""
        tracking = self.tracking.result()
        excluded = {"outliers": len(self.outliers), "ticks": self.excluded_ticks,
                    "unmeasured": len(getattr(self.truth, "unmeasured", ()))}
        if self.measured is None:
            return tracking, {}, excluded
        self.measured.fold(self.outliers)
        interpolated = {k.replace("_mm", "_interpolated_mm"): tracking.pop(k)
                        for k in ("rms_error_mm", "max_error_mm", "rms_error_axis_mm")}
        tracking.update(self.measured.result())
        excluded.update(outlier_samples=self.measured.outliers,
                        unmeasured_samples=self.measured.unmeasured,
                        after_last_sample_ticks=self.after_last_ticks)
        return tracking, interpolated, excluded

    def _refresh_budget(self) -> dict:
        """Each refresh's p50 … max [µs], the predictor's period [µs] and how many refreshes
        took longer (every refresh of the run, settling included)."""
        h = self.refreshes
        edge = int(min(self.period_ns // h.resolution, h.counts.size))
        over = int(h.counts[edge:].sum()) + sum(ns > self.period_ns for ns in h.overflow)
        return {**h.stats_us(), "refreshes": h.n, "period_us": self.period_ns / 1e3,
                "over_period": over}

    def result(self, controller) -> LoopResult:
        tracking, interpolated, excluded = self._scores()
        with np.errstate(invalid="ignore", divide="ignore"):
            horizon_error = np.sqrt(self.horizon2 / self.n_horizons)  # NaN where no refresh
        ticks = np.array([t for t, _ in self.kept_horizons], dtype=np.int64)
        points = (np.array([h for _, h in self.kept_horizons]) if self.kept_horizons
                  else np.zeros((0, self.N, 3)))
        stamps = np.array([t for t, _ in self.kept_samples], dtype=float)
        samples = (np.array([z for _, z in self.kept_samples]) if self.kept_samples
                   else np.zeros((0, 3)))
        return LoopResult(
            settings=self.settings, trace=self.trace.arrays(), stride=self.trace.stride,
            tracking=tracking, interpolated=interpolated,
            measured=() if self.measured is None else self.measured.samples(),
            tick_us=self.ticks.stats_us(),
            yardstick_us=self.yardstick.stats_us(),
            tick_parts_us={name: h.stats_us() for name, h in self.parts.items()},
            control_tick_us=self.parts["step"].stats_us(), horizon_error=horizon_error,
            refresh_us=self._refresh_budget(),
            controller_stats=controller_stats(controller), saturated_ticks=self.saturated_ticks,
            predictor_counts=dict(controller.predictor_counts),
            horizons=(ticks, points), samples=(stamps, samples),
            excluded=excluded,
            envelope=self.envelope.result(), segments=tuple(self.segments or ()),
        )


def event_counts(controller, plant) -> dict[str, int]:
    """What the controller and the plant counted so far, flat: the predictor's and the gate's
    counts, the MPC's fallbacks by kind (``fallback_plan`` …), its failed solves
    (``qp_failures``) and the encoder readings a faulty plant held (``encoder_held_ticks``)."""
    counts = {k: int(v) for k, v in controller.predictor_counts.items()}
    stats = controller_stats(controller)
    for kind, n in (stats.get("fallbacks") or {}).items():
        counts[f"fallback_{kind}"] = int(n)
    counts["qp_failures"] = int(sum((stats.get("failures") or {}).values()))
    counts["encoder_held_ticks"] = int(getattr(plant, "held_ticks", 0))
    return counts


def controller_stats(controller) -> dict:
    """The controller's counters as a plain dict, with ``fallback_total``."""
    stats_obj = getattr(controller, "stats", None)
    if dataclasses.is_dataclass(stats_obj):
        stats = dataclasses.asdict(stats_obj)
        stats["fallback_total"] = int(getattr(stats_obj, "fallback_total", 0))
        return stats
    return dict(stats_obj or {})
