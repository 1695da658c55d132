"""`rhmpc sil`: the deployment on one machine in real time — sensor, predictor, controller
(the exported C) and robot (the simulator) as separate processes over UDP."""

from __future__ import annotations

import argparse
import json
import sys

from rhmpc.cli import COMMANDS
from rhmpc.cli.options import add_model_option, add_recording_options, add_run_options
from rhmpc.cli.simulate import config_from_args
from rhmpc.errors import UsageError, one_line


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "sil", help=COMMANDS["sil"],
        description="Software in the loop, in real time: the sensor (a recording or a "
        "scenario's sensor, at its rate and latency), the predictor (any predictor), the "
        "controller (the exported C built with CMake, on an absolute 2-kHz clock, SCHED_FIFO "
        "and a pinned core where the host permits) and the robot (the simulator stepping in "
        "real time) run as separate processes and talk over UDP on loopback, every message "
        "sealed under a key made for the run (the wire format of the deployment guide): only "
        "the run's processes can command. Reports deadline misses, the controller's wake-up "
        "latency beside the host's own (cyclictest where installed, else the controller's "
        "loop without its work), the sensor-to-torque latency, packets lost, datagrams "
        "dropped, and the tracking error at the measured instants beside the in-process "
        "simulation's. A part that dies, the tool off the POI by more than 5 mm (or 1 mm RMS "
        "over a second) or more than 20 %% of a second's deadlines missed stops every process "
        "in the safe state and exits 1 with the cause. Ctrl-C stops every process.")
    p.add_argument("--predictor", help="predictor name (default generalized); any predictor "
                   "runs in its own process and sends its forecasts to the controller")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--scenario", help="heart-motion scenario (rhmpc data list)")
    src.add_argument("--data", metavar="FILE", help="a recording (CSV, NPZ, MAT, a ROS bag "
                     "with --topic, or a shipped name such as hamlyn-phantom)")
    add_recording_options(p)
    p.add_argument("--poi", type=int, metavar="N", help="the point of interest of a --data file "
                   "of several tracked points (numbered from 1)")
    p.add_argument("--seed", type=int, help="seed of every random draw (default 0)")
    add_run_options(p)
    p.add_argument("--priority", type=int, default=80, help="SCHED_FIFO priority of the "
                   "controller and the host probe where permitted (default 80; the robot 10 "
                   "below, the sensor 20 below)")
    p.add_argument("--cpu", type=int, help="the processor the controller and the probe are "
                   "pinned to (default: the last one)")
    p.add_argument("--no-internal", action="store_true", help="the controller's own RLS does "
                   "not learn from the samples: forecasts alone drive it, and a lost one holds "
                   "the last points")
    p.add_argument("--port", type=int, metavar="P", help="the controller's UDP port on "
                   "loopback (the predictor's P+1, the robot's P+2; default: any free ones)")
    p.add_argument("--tracker", metavar="ros2:TOPIC", help="take the samples from a ROS 2 "
                   "topic of geometry_msgs/PoseStamped or PoseArray (the POI the --poi-th) "
                   "through a bridge in the sensor's place, and publish the forecasts "
                   "(nav_msgs/Path on /rhmpc/forecast_cp) and the run's status "
                   "(diagnostic_msgs/DiagnosticStatus on /rhmpc/status); the recording still "
                   "fits the predictor and registers the tracker's frame (needs rhmpc[ros2])")
    p.add_argument("--console", metavar="ros2:NAMESPACE", help="command an arm over ROS 2 "
                   "through a bridge in the robot's place: its readings from NAMESPACE/"
                   "measured_js, the torques to NAMESPACE/servo_jf (sensor_msgs/JointState, "
                   "the dVRK's CRTK names); refused without --allow-unauthenticated")
    p.add_argument("--allow-unauthenticated", action="store_true", help="accept a --console "
                   "over ROS 2, which authenticates nothing: any process on its DDS domain "
                   "could command the arm or forge its readings")
    add_model_option(p)
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=run)


def _row(label: str, value) -> str:
    return f"  {label:<34} {value}"


def _p(d: dict, unit: str) -> str:
    if d.get("p50") is None:
        return "none"
    return f"p50 {d['p50']:g} / p99 {d['p99']:g} / max {d['max']:g} {unit}"


def table(r: dict) -> str:
    """The report as lines of text."""
    lost = sum(v.get("lost", 0) for v in r["packets"].values())
    dropped = {}
    for counts in r["dropped"].values():
        for reason, n in counts.items():
            dropped[reason] = dropped.get(reason, 0) + n
    drops = ", ".join(f"{n} {reason}" for reason, n in dropped.items() if n) or "none"
    braked = "as its console's drivers decide" if r["robot_safe_state_ticks"] is None \
        else f"{r['robot_safe_state_ticks']} ticks"
    lines = [
        f"rhmpc sil: {r['predictor']} on {r['recording']}, {r['duration_s']:g} s in real time",
        _row("ticks, deadline misses", f"{r['ticks']}, {r['deadline_misses']} "
             f"({100 * r['deadline_misses'] / max(r['ticks'], 1):.3g} %)"),
        _row("controller wake-up latency", _p(r["wakeup_latency_us"], "us")),
        _row("host wake-up latency", _p(r["host_wakeup_latency_us"], "us")
             + f" ({r['host_wakeup_latency_us']['tool']}; the misses the host alone causes: "
             f"{100 * r['host_wakeup_latency_us']['late_periods']:.3g} %)"),
        _row("controller step", _p(r["controller_step_us"], "us")),
        _row("sensor to torque", _p(r["sensor_to_torque_ms"], "ms")),
        _row("packets lost", f"{lost} (ticks without a new reading {r['stale_encoders']}, "
             f"torques missed {r['torques_missed']}, robot braked {braked})"),
        _row("readings fused late", f"{r['late_readings']['fused']} (at most "
             f"{r['late_readings']['max_delay_ticks']} ticks late)"),
        _row("datagrams dropped", drops),
        _row("a lost forecast falls back to", r["forecast_fallback"]),
        _row("RMS error at measured instants", f"{r['rms_error_mm']:.4f} mm (in-process "
             f"{r['in_process_rms_error_mm']:.4f} mm)"),
        _row("real time", r["realtime"]["controller"]),
        _row("host load (1, 5, 15 min)", f"{r['host_load']['before']} -> "
             f"{r['host_load']['after']} on {r['host_load']['cpus']} CPUs"),
    ]
    return "\n".join(lines)


def _say(text: str) -> None:
    print(f"rhmpc sil: {text}", file=sys.stderr)


def run(args: argparse.Namespace) -> int:
    from rhmpc.runtime.deployment import DeploymentError, SilSettings, run_sil
    from rhmpc.runtime.ros2.names import endpoint

    config = config_from_args(args)
    if config.predictor == "exact":
        raise UsageError("rhmpc sil needs a predictor ('exact' reads the future)")
    try:
        bridges = {name: endpoint(getattr(args, name), f"--{name}")
                   for name in ("tracker", "console") if getattr(args, name) is not None}
        settings = SilSettings(priority=args.priority, cpu=args.cpu,
                               internal=not args.no_internal, port=args.port,
                               allow_unauthenticated=args.allow_unauthenticated, **bridges)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if settings.tracker is not None:
        _say(f"the samples of {settings.tracker} are not authenticated (ROS 2 without SROS2): "
            "any process on the DDS domain can publish them, within the receivers' bounds")
    try:
        report = run_sil(config, settings, progress=_say)
    except DeploymentError as exc:  # not the input's fault: exit 1, on one line
        print(f"rhmpc sil: error: {one_line(exc)}", file=sys.stderr)
        return 1
    print(json.dumps(report, indent=2) if args.json else table(report))
    return 0
