"""The joint observer: textbook equations, the Kalman gain against the Riccati recursion, and
velocity estimation from quantised encoders."""

import numpy as np
import pytest

from rhmpc.control.observer import JointObserver, ObserverSettings
from robots import linearize, load_robot

TS = 0.5e-3


@pytest.fixture(scope="module")
def phantom_arm():
    robot = load_robot("phantom")
    return robot, linearize(robot, Ts=TS)


def test_fused_steps_equal_the_textbook_filter(phantom_arm):
    robot, arm = phantom_arm
    observer = JointObserver(arm, robot.encoder_resolution)
    rng = np.random.default_rng(3)
    n = arm.nu
    H = np.hstack([np.eye(n), np.zeros((n, n))])
    x_prior = np.zeros(2 * n)
    for _ in range(200):
        q = arm.q0 + rng.normal(size=n) * 1e-3
        u = rng.normal(size=n) * 0.1
        x = x_prior + observer.L @ (q - arm.q0 - H @ x_prior)
        np.testing.assert_allclose(observer.correct(q), x, rtol=0, atol=1e-12)
        observer.predict(u)
        x_prior = arm.A @ x + arm.B @ u
        np.testing.assert_allclose(observer.x_prior, x_prior, rtol=0, atol=1e-12)


def test_gain_is_the_limit_of_the_riccati_recursion(phantom_arm):
    robot, arm = phantom_arm
    settings = ObserverSettings(acceleration_noise=20.0)
    observer = JointObserver(arm, robot.encoder_resolution, settings)
    n = arm.nu
    G = np.vstack([0.5 * TS**2 * np.eye(n), TS * np.eye(n)])
    Q = settings.acceleration_noise**2 * G @ G.T
    R = np.diag(robot.encoder_resolution**2 / 12.0)
    H = np.hstack([np.eye(n), np.zeros((n, n))])
    P = np.eye(2 * n)  # time-varying Kalman filter from an arbitrary prior
    for _ in range(20000):
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
        P = arm.A @ (P - K @ H @ P) @ arm.A.T + Q
    np.testing.assert_allclose(observer.L, K, rtol=1e-6, atol=1e-9)


def test_velocity_from_quantised_encoders_beats_differentiation(phantom_arm):
    robot, arm = phantom_arm
    observer = JointObserver(arm, robot.encoder_resolution)
    res = robot.encoder_resolution
    t = np.arange(4000) * TS
    omega = 2 * np.pi * 1.2  # a heartbeat-like joint oscillation
    amp = 0.02  # [rad]
    q = arm.q0 + amp * np.sin(omega * t)[:, None] * np.ones(arm.nu)
    v = amp * omega * np.cos(omega * t)[:, None] * np.ones(arm.nu)
    qd = amp * -(omega**2) * np.sin(omega * t)[:, None] * np.ones(arm.nu)
    M = TS * np.linalg.pinv(arm.B[arm.nu :])  # the model's inertia: u = M q̈
    est = []
    for k in range(len(t)):
        x = observer.correct(np.rint(q[k] / res) * res)
        est.append(x[arm.nu :].copy())
        # the torque of this motion in the model (what the MPC torque is in the loop)
        observer.predict(M @ qd[k])
    est = np.array(est)[1000:]
    err = np.sqrt(np.mean((est - v[1000:]) ** 2, axis=0))
    naive = np.diff(np.rint(q / res) * res, axis=0)[1000:] / TS
    naive_err = np.sqrt(np.mean((naive - v[1001:]) ** 2, axis=0))
    assert np.all(err < 0.2 * naive_err), (err, naive_err)
    assert np.all(err < 0.02)  # [rad/s], vs a peak velocity of 0.15 rad/s
