"""The report of a deployment: what its parts wrote, the tool scored where the POI was
measured (as the in-process run is), the packets and the drops, the timing beside the host's."""

from __future__ import annotations

import os
from io import BytesIO
from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.experiment import RunConfig
from rhmpc.positions import embed3
from rhmpc.runtime import host, ros2
from rhmpc.sim.loop.metrics import MeasuredScore

__all__ = ["collect", "report", "score"]


def collect(folder: Path, tool: str, config: RunConfig):
    """The parts' documents, the controller's timing arrays, the robot's log and the probe's."""
    documents = {name: io.read_json(folder / f"{name}.json", track=False)
                 for name in ("controller", "robot", "predictor", "sensor")}
    arrays = {name: host.read_int64(folder / f"controller.{name}")
              for name in ("wake", "work", "step", "s2t")}
    q = np.load(BytesIO(io.read_bytes(folder / "robot_q.npy", track=False)))
    return documents, arrays, q, host.read_probe(folder / "host", tool, config.loop.Ts)


def score(run, q: np.ndarray, outliers: list[float], measured) -> dict:
    """The tool after each tick against the POI where it was measured (``measured``: a
    recording's or a tracker's samples, at their instants) or at every tick (a synthetic
    motion, None), as the in-process run."""
    loop = run.config.loop
    ticks = loop.ticks
    done = np.isfinite(q).all(axis=1)
    ee = np.full((ticks, 3), np.nan)
    ee[done] = [run.robot.ee_position(row) for row in q[done]]
    if measured is not None:
        t, z = measured
        placed = run.anchor + embed3(np.asarray(z, dtype=float).reshape(len(t), -1)
                                     - run.truth.center)
    else:
        t = (np.arange(ticks) + 1) * loop.Ts
        placed = run.anchor + embed3(run.truth.window(1, ticks + 1))
    score = MeasuredScore(t, placed, loop.settling_ticks * loop.Ts, ticks * loop.Ts, loop.Ts)
    score.add(0, ee)
    score.fold(outliers)
    return score.result()


def packets(documents: dict) -> dict:
    """Per kind: sent, and what its receivers took, lost and dropped."""
    controller, robot, predictor = (documents[k] for k in ("controller", "robot", "predictor"))
    sent = {"measured_cp": documents["sensor"]["sent"], "forecast_cp": predictor["forecasts"],
            "measured_js": controller["ticks"] + 1, "servo_jf": controller["ticks"]}
    out = {kind: {"sent": sent[kind], "received": controller["received"][kind],
                  "lost": controller["lost"][kind]}
           for kind in ("measured_cp", "forecast_cp", "measured_js")}
    out["servo_jf"] = {"sent": sent["servo_jf"], "received": robot["arrivals"]["received"][
        "servo_jf"], "lost": robot["arrivals"]["lost"]["servo_jf"]}
    out["measured_cp_at_predictor"] = {"sent": sent["measured_cp"],
                                       "received": predictor["arrivals"]["received"][
                                           "measured_cp"],
                                       "lost": predictor["arrivals"]["lost"]["measured_cp"]}
    return out


def report(config: RunConfig, built, internal: bool, documents: dict, arrays: dict,
           host_latency: dict, score: dict, in_process: dict, load: tuple) -> dict:
    """The run's report: timing, packets, drops, the score beside the in-process one."""
    controller, robot = documents["controller"], documents["robot"]
    fallback = f"the controller's own {built.internal} RLS" if internal else "hold"
    return {
        "recording": config.data or config.scenario, "predictor": config.predictor,
        "duration_s": config.loop.duration, "ticks": controller["ticks"],
        "deadline_misses": controller["deadline_misses"],
        "wakeup_latency_us": host.percentiles(arrays["wake"] * 1e-3),
        "host_wakeup_latency_us": host_latency,
        "tick_work_us": host.percentiles(arrays["work"] * 1e-3),
        "controller_step_us": host.percentiles(arrays["step"] * 1e-3),
        "sensor_to_torque_ms": {k: None if v is None else round(v * 1e-3, 3) for k, v in
                                host.percentiles(arrays["s2t"] * 1e-3).items()},
        "packets": packets(documents),
        "dropped": {"controller": controller["dropped"],
                    "predictor": documents["predictor"]["arrivals"]["dropped"],
                    "robot": robot["arrivals"]["dropped"]},
        "stale_encoders": controller["stale_encoders"],
        "late_readings": {"fused": controller["late_readings"],
                          "max_delay_ticks": controller["delay_max"]},
        "torques_missed": robot["torques_missed"], "torques_late": robot["torques_late"],
        "robot_safe_state_ticks": robot["safe_state_ticks"],
        "forecasts_rejected": controller["forecasts_rejected"],
        "forecast_fallback": fallback,
        "points_served_ticks": controller["served"],
        "rms_error_mm": score["rms_error_mm"], "max_error_mm": score["max_error_mm"],
        "scored_samples": score["scored_samples"],
        "in_process_rms_error_mm": in_process["rms_error_mm"],
        "supervisor_tool_error_mm": controller["tool_error_mm"],
        "fallbacks": controller["fallbacks"], "failures": controller["failures"],
        "predictor_forecast_ms": documents["predictor"]["forecast_ms"],
        "realtime": {"controller": controller["realtime"], "robot": robot["scheduling"],
                     "sensor": documents["sensor"]["scheduling"],
                     "predictor": documents["predictor"]["scheduling"]},
        "host_load": {"before": [round(v, 2) for v in load[0]],
                      "after": [round(v, 2) for v in load[1]], "cpus": os.cpu_count()},
    } | ros2.report(documents)
