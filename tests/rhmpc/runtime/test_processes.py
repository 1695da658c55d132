"""The simulated robot's drivers: a missing torque holds, a silence brakes under gravity."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from rhmpc.robots import load_robot
from rhmpc.runtime.processes import BRAKE_S, WATCHDOG_TICKS, Drivers


def test_a_silent_controller_leaves_the_arm_braked_not_pushed():
    robot = load_robot("phantom")
    drivers, Ts = Drivers(robot, 0.5e-3), 0.5e-3
    q = robot.q0.copy()
    gravity = pin.computeGeneralizedGravity(robot.model, robot.create_data(), q)
    np.testing.assert_allclose(drivers.torque(None, q), gravity)  # before any torque: held up
    assert drivers.missed == drivers.safe == 0  # waiting, not missing
    command = np.array([0.2, -0.1, 0.05])
    np.testing.assert_array_equal(drivers.torque(command, q), command)
    for _ in range(WATCHDOG_TICKS):  # a short silence: the last torque holds
        np.testing.assert_array_equal(drivers.torque(None, q), command)
    moved = q + np.array([1e-3, 0.0, -2e-3])  # the arm still moves: brake against it
    tau = drivers.torque(None, moved)
    speed = (moved - q) / Ts
    gravity = pin.computeGeneralizedGravity(robot.model, robot.create_data(), moved)
    expected = np.clip(gravity - robot.mass_matrix(moved) @ speed / BRAKE_S,
                       -robot.torque_limit, robot.torque_limit)
    np.testing.assert_allclose(tau, expected, rtol=1e-12)
    assert drivers.missed == WATCHDOG_TICKS + 1 and drivers.safe == 1
    np.testing.assert_array_equal(drivers.torque(command, moved), command)  # torques again


def test_bad_settings_of_sil_are_one_line(capsys):
    from rhmpc.cli import main

    for argv, words in ((["--priority", "0"], "priority must be 1"),
                        (["--cpu", "100000"], "cpu 100000 is not one"),
                        (["--predictor", "exact"], "needs a predictor"),
                        (["--port", "80"], "port must be 1024")):
        assert main(["sil", "--duration", "2", *argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0], err
