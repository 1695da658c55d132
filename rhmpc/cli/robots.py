"""`rhmpc robots`: the registered robots, or the robot of a file, at their home postures."""

from __future__ import annotations

import argparse
import json

import numpy as np

from rhmpc.cli import COMMANDS
from rhmpc.robots import ROBOTS, load_robot


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "robots",
        help=COMMANDS["robots"],
        description="List the registered robots: DOF, home posture, end-effector position, "
        "torque limits and the conditioning of the end-effector Jacobian at home. With --robot "
        "FILE.toml, check that robot file and show its robot (docs: your robot, from its URDF "
        "to its drivers).",
    )
    p.add_argument("--robot", metavar="NAME|FILE.toml", help="only this robot: a registered "
                   "name or a robot file (its URDF, joints, tool, home; checked before use)")
    p.add_argument("--json", action="store_true", help="print machine-readable JSON")
    p.set_defaults(func=run)


def robot_summary(name: str) -> dict:
    """Facts about one robot at its home posture (SI units, angles in degrees)."""
    robot = load_robot(name)
    sv = np.linalg.svd(robot.ee_jacobian(robot.q0), compute_uv=False)
    return {
        "name": robot.name,
        "dof": robot.nv,
        "q0_deg": np.degrees(robot.q0).round(2).tolist(),
        "ee_position_mm": (1e3 * robot.ee_position(robot.q0)).round(2).tolist(),
        "torque_limit_Nm": robot.torque_limit.round(4).tolist(),
        "jacobian_singular_values_m": sv.round(4).tolist(),
        "jacobian_condition": float(sv[0] / sv[-1]),
        "description": robot.description,
    }


def _vec(values: list[float], decimals: int) -> str:
    return "(" + ", ".join(f"{x:.{decimals}f}" for x in values) + ")"


def run(args: argparse.Namespace) -> int:
    rows = [robot_summary(name) for name in ((args.robot,) if args.robot else ROBOTS)]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    head = f"{'robot':<17} {'DOF':>3}  {'home q0 [deg]':<22} {'EE at home [mm]':<24} "
    head += f"{'torque limit [N·m]':<25} {'J sing. values [m]':<24} cond"
    print(head)
    for r in rows:
        print(
            f"{r['name']:<17} {r['dof']:>3}  {_vec(r['q0_deg'], 1):<22} "
            f"{_vec(r['ee_position_mm'], 1):<24} {_vec(r['torque_limit_Nm'], 3):<25} "
            f"{_vec(r['jacobian_singular_values_m'], 3):<24} {r['jacobian_condition']:.2f}"
        )
    return 0
