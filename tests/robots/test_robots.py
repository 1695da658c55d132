"""Robot models: dynamics and kinematics against independent references."""

import numpy as np
import pinocchio as pin
import pytest

from rhmpc.robots import ROBOTS, load_robot
from rhmpc.robots.model import forward_dynamics


@pytest.fixture(scope="module", params=ROBOTS)
def robot(request):
    return load_robot(request.param)


def random_state(robot, rng):
    lower, upper = robot.position_limits
    q = rng.uniform(lower, upper)
    v = rng.normal(size=robot.nv)
    tau = rng.normal(size=robot.nv) * robot.torque_limit
    return q, v, tau


def test_aba_equals_inverse_mass_matrix_times_bias_free_torque(robot):
    """ABA(q, v, τ) = M(q)⁻¹ (τ − h(q, v)), with M from CRBA and h from RNEA(q, v, 0); a model
    with mimic bodies has no ABA: there the check is that forward_dynamics solves M q̈ = τ − h
    (tests/robots/test_phantom_sources.py checks it against the projected five-joint tree)."""
    rng = np.random.default_rng(1)
    data = robot.create_data()
    for _ in range(20):
        q, v, tau = random_state(robot, rng)
        ddq = forward_dynamics(robot.model, data, q, v, tau).copy()
        M = pin.crba(robot.model, data, q).copy()
        M = np.triu(M) + np.triu(M, 1).T
        h = pin.rnea(robot.model, data, q, v, np.zeros(robot.nv)).copy()
        ref = np.linalg.solve(M, tau - h)
        np.testing.assert_allclose(ddq, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


def test_mass_matrix_includes_armature(robot):
    rng = np.random.default_rng(2)
    q, _, _ = random_state(robot, rng)
    q = robot.q0 if robot.coupling else q
    model = robot.model.copy()
    model.armature[:] = 0.0
    M_bare = pin.crba(model, model.createData(), q)
    M_bare = np.triu(M_bare) + np.triu(M_bare, 1).T
    np.testing.assert_allclose(robot.mass_matrix(q) - M_bare, np.diag(robot.armature), atol=1e-14)


def test_frame_jacobian_matches_finite_differences(robot):
    rng = np.random.default_rng(3)
    h = 1e-6
    for _ in range(5):
        q, _, _ = random_state(robot, rng)
        J = robot.ee_jacobian(q)
        J_fd = np.column_stack(
            [
                (robot.ee_position(q + h * e) - robot.ee_position(q - h * e)) / (2 * h)
                for e in np.eye(robot.nq)
            ]
        )
        np.testing.assert_allclose(J, J_fd, atol=1e-8)


def test_home_posture_is_well_conditioned(robot):
    sv = np.linalg.svd(robot.ee_jacobian(robot.q0), compute_uv=False)
    assert sv[-1] > 0.05  # [m/rad]
    assert sv[0] / sv[-1] < 5.0


def test_unknown_robot_lists_valid_names():
    with pytest.raises(ValueError,
                       match="valid robots: phantom, phantom-cavusoglu, finger_edu, ur5"):
        load_robot("puma")


def test_posture_outside_limits_is_rejected():
    robot = load_robot("phantom")
    with pytest.raises(ValueError, match=r"joint 'elbow' at 250.0 deg is outside its limits"):
        robot.check_posture(np.radians([0.0, 0.0, 250.0]))
    with pytest.raises(ValueError, match=r"coupled limit -124.0 ≤ \[0.0, 1.0, 1.0\]·q ≤ 119.0"):
        robot.check_posture(np.radians([0.0, 100.0, 40.0]))
    with pytest.raises(ValueError, match="shape"):
        robot.check_posture(np.zeros(4))
    with pytest.raises(ValueError, match="non-finite"):
        robot.check_posture(np.array([0.0, np.nan, 1.0]))


def test_phantom_matches_published_figures():
    """mahilab/Phantom: PhantomModel.hpp (Eta, masses, l1, l2, limits), README.md (Maxon RE 25
    118743: stall torque, rotor inertia, torque constant, no-load current; HEDM-5500)."""
    robot = load_robot("phantom")
    eta = np.array([13.3, 11.2, 11.2])
    np.testing.assert_allclose(robot.torque_limit, eta * 0.129)
    np.testing.assert_allclose(robot.rotor_inertia, eta**2 * 1.03e-6)
    np.testing.assert_allclose(robot.armature, [eta[0] ** 2 * 1.03e-6, eta[1] ** 2 * 1.03e-6, 0])
    np.testing.assert_allclose(robot.damping, 0.0)
    np.testing.assert_allclose(robot.coulomb_friction, 0.0234 * 0.0263 * eta)
    np.testing.assert_allclose(robot.encoder_resolution, 2 * np.pi / (4096 * eta))
    lower, upper = robot.position_limits
    np.testing.assert_allclose(np.degrees(lower), [-90, -119, 35], atol=1e-5)
    np.testing.assert_allclose(np.degrees(upper), [90, 124, 155], atol=1e-5)
    # Upper arm horizontal, forearm vertical: tip at (l1, 0, −l2).
    np.testing.assert_allclose(robot.ee_position(robot.q0), [0.20955, 0.0, -0.169545])
    total = sum(inertia.mass for inertia in robot.model.inertias)
    np.testing.assert_allclose(total, 0.026220 + 0.026146 + 0.267840 + 0.215420 + 0.361590,
                               atol=1e-9)
