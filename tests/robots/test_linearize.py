"""The MPC's linear model against expm, a closed form, and an ODE integration."""

import dataclasses

import numpy as np
import pytest
import scipy.linalg
from scipy.integrate import solve_ivp

from rhmpc.robots import ROBOTS, linearize, load_robot


@pytest.fixture(scope="module", params=ROBOTS)
def arm(request):
    return linearize(load_robot(request.param), Ts=0.5e-3)


def test_shapes_and_home_output(arm):
    assert (arm.A.shape, arm.B.shape, arm.C.shape, arm.y0.shape) == ((6, 6), (6, 3), (3, 6), (3,))
    np.testing.assert_allclose(arm.output(np.zeros(6)), arm.y0)


def test_discretisation_matches_expm_of_augmented_matrix(arm):
    Ts = arm.Ts
    aug = np.zeros((9, 9))
    aug[:6, :6], aug[:6, 6:] = arm.Ac, arm.Bc
    Phi = scipy.linalg.expm(aug * Ts)
    np.testing.assert_allclose(arm.A, Phi[:6, :6], atol=1e-15)
    np.testing.assert_allclose(arm.B, Phi[:6, 6:], rtol=1e-12, atol=1e-18)


def test_discretisation_matches_double_integrator_closed_form(arm):
    Ts, Minv, eye = arm.Ts, np.linalg.inv(arm.M0), np.eye(3)
    A = np.block([[eye, Ts * eye], [0 * eye, eye]])
    B = np.vstack([Ts**2 / 2 * Minv, Ts * Minv])
    np.testing.assert_allclose(arm.A, A, atol=1e-15)
    np.testing.assert_allclose(arm.B, B, rtol=1e-10)


def test_one_step_equals_integrated_continuous_system(arm):
    rng = np.random.default_rng(4)
    x0 = rng.normal(size=6) * 1e-2
    u = rng.normal(size=3) * arm.torque_limit * 0.1
    sol = solve_ivp(
        lambda t, x: arm.Ac @ x + arm.Bc @ u, (0, arm.Ts), x0, rtol=1e-12, atol=1e-15
    )
    np.testing.assert_allclose(arm.A @ x0 + arm.B @ u, sol.y[:, -1], rtol=1e-8, atol=1e-13)


def test_output_matrix_is_the_jacobian():
    robot = load_robot("phantom")
    arm = linearize(robot)
    dq = np.array([1e-4, -2e-4, 1.5e-4])
    y_lin = arm.output(np.concatenate([dq, np.zeros(3)]))
    y_true = robot.ee_position(robot.q0 + dq)
    assert np.linalg.norm(y_lin - y_true) < 1e-7  # second-order in |dq| (~1e-8 m)


def test_bad_inputs_raise():
    robot = load_robot("phantom")
    with pytest.raises(ValueError, match="Ts"):
        linearize(robot, Ts=0.0)
    with pytest.raises(ValueError, match="outside its limits"):
        linearize(robot, q0=np.radians([100.0, 0.0, 90.0]))


def test_linear_arm_carries_the_robot_and_its_limits():
    """The envelope's limits are the URDF's: PHANToM joint ranges and velocity limit."""
    import xml.etree.ElementTree as ET

    from rhmpc.robots.registry import urdf_path

    robot = load_robot("phantom")
    arm = linearize(robot)
    assert arm.robot is robot
    joints = ET.parse(urdf_path("phantom_premium_1_5a.urdf")).iter("joint")
    limits = [j.find("limit") for j in joints
              if j.get("type") == "revolute" and j.find("mimic") is None]
    lower = np.array([float(e.get("lower")) for e in limits])
    upper = np.array([float(e.get("upper")) for e in limits])
    velocity = np.array([float(e.get("velocity")) for e in limits])
    np.testing.assert_array_equal(arm.position_limits[0], lower)
    np.testing.assert_array_equal(arm.position_limits[1], upper)
    np.testing.assert_array_equal(arm.velocity_limit, velocity)
    bare = dataclasses.replace(arm, robot=None)
    assert bare.position_limits is None and bare.velocity_limit is None
