"""The joint observer: textbook equations, the Kalman gain against the Riccati recursion, and
velocity estimation from quantised encoders."""

import numpy as np
import pytest

from rhmpc.control.observer import JointObserver, ObserverSettings
from rhmpc.robots import linearize, load_robot

TS = 0.5e-3


@pytest.fixture(scope="module")
def phantom_arm():
    robot = load_robot("phantom")
    return robot, linearize(robot, Ts=TS)


def test_fused_steps_equal_the_textbook_filter(phantom_arm):
    robot, arm = phantom_arm  # readings 1 mrad apart: the innovation gate off
    observer = JointObserver(arm, robot.encoder_resolution, ObserverSettings(innovation_gate=0))
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
    assert observer.counts == {"held": 0, "reacquired": 0}  # healthy readings all fused


def _moving(observer, arm, ticks: int, reading, accel: float = 5.0):
    """Drive the observer with a model-consistent motion from rest under a constant joint
    acceleration ``accel`` [rad/s²] (the torque that acts), the encoder giving
    ``reading(k, q)``; returns the estimates (ticks, 2n) and the true velocities (ticks, n)."""
    M = TS * np.linalg.pinv(arm.B[arm.nu:])
    a = np.full(arm.nu, accel)
    q, v, est, vel = arm.q0.copy(), np.zeros(arm.nu), [], []
    for k in range(ticks):
        est.append(observer.correct(reading(k, q)).copy())
        vel.append(v.copy())
        observer.predict(M @ a)
        q, v = q + TS * (v + TS * a / 2), v + TS * a
    return np.array(est), np.array(vel)


def test_a_stuck_encoder_is_held_out_and_faults_after_the_timeout(phantom_arm):
    """A joint driven by a torque whose encoder stops: the model moves on, the reading does not.
    The filter absorbs a steady acceleration a as the innovation bias a Ts / L_v, so the gate
    sees an acceleration past γ √S L_v / Ts (≈ 100 rad/s² on the PHANToM at γ = 5): a loop
    fighting a stuck joint saturates its torque and gets there; 400 rad/s² here."""
    robot, arm = phantom_arm
    res = robot.encoder_resolution
    observer = JointObserver(arm, res)
    stuck, first_held = {}, []

    def reading(k, q):
        if observer.held and not first_held:
            first_held.append(k)
        q = np.rint(q / res) * res
        if k >= 100:  # joint 1 sticks at its reading of tick 100
            q[1] = stuck.setdefault("q", q[1])
        return q

    est, vel = _moving(observer, arm, 200 + observer.timeout_ticks, reading, accel=400.0)
    assert first_held[0] - 100 <= 10  # within 5 ms
    assert observer.held >= observer.timeout_ticks and observer.faulted
    assert observer.counts["reacquired"] == 0  # it never moves again
    # held whole, the reading is predicted: the estimate keeps moving with the torque
    np.testing.assert_allclose(est[-1, arm.nu:], vel[-1], rtol=0.05)


def test_a_reading_that_moves_again_is_taken_again(phantom_arm):
    robot, arm = phantom_arm
    res = robot.encoder_resolution
    observer = JointObserver(arm, res)
    ticks = observer.settings.reacquire_ticks

    def reading(k, q):  # joint 0 is offset by 2 mrad from tick 50 (a disturbance, alive)
        q = np.rint(q / res) * res
        return q + np.array([2e-3, 0.0, 0.0]) * (k >= 50)

    est, vel = _moving(observer, arm, 50 + 2 * ticks + 10, reading)
    assert observer.counts == {"held": ticks, "reacquired": 1}
    assert not observer.faulted and observer.held == 0
    q = arm.q0 + est[-1, :arm.nu]
    assert abs(est[-1, 0] - est[-1, 1] - 2e-3) < 2 * res[0]  # the angle moved to the reading
    # [rad/s]: the velocity from Δ over the 10-ms hold is within 0.014
    np.testing.assert_allclose(est[-1, arm.nu:], vel[-1], atol=0.03)
    assert np.all(np.isfinite(q))


def test_a_joint_the_prediction_drifts_from_during_a_hold_is_no_suspect(phantom_arm):
    """A reading held for joint 0 (a step past its gate, then a quantum further: alive) while
    the open-loop prediction carries joint 1, whose encoder reads an arm at rest, past its own
    gate: the hold ends on joint 0's change alone; joint 1's steady reading is no fault."""
    robot, arm = phantom_arm
    res = robot.encoder_resolution
    observer = JointObserver(arm, res)
    x = np.zeros(2 * arm.nu)
    x[arm.nu + 1] = 0.05  # [rad/s]: the estimate believes joint 1 moves
    observer.reset(x)
    step = 3.0 * observer.gate[0]
    for k in range(2 * observer.timeout_ticks):
        q = arm.q0.copy()
        q[0] += step + res[0] * (k > 0)
        observer.correct(q)
        observer.predict(np.zeros(arm.nu))
        if k == observer.settings.reacquire_ticks - 1:  # the prediction is past joint 1's gate
            assert abs(observer.x_prior[1]) > observer.gate[1]
    assert observer.counts["reacquired"] == 1 and not observer.faulted


def test_readings_that_are_not_finite_are_held_out(phantom_arm):
    robot, arm = phantom_arm
    observer = JointObserver(arm, robot.encoder_resolution)
    for bad in (np.array([np.nan, 0.0, 0.0]), np.array([np.inf, 1e300, -np.inf])):
        observer.reset()
        x = observer.correct(arm.q0 + bad)
        assert np.all(x == 0.0) and observer.held == 1  # the prediction (at rest at q0)
        np.testing.assert_array_equal(observer.reading, arm.q0)


def test_a_reading_that_is_not_finite_is_held_out_after_a_reacquire_too(phantom_arm):
    """A hold that ends (the reading moved again) opens a grace in which readings are fused
    whatever the gate says: a NaN then (a reading that did not come) is still held out, and
    the estimate stays finite."""
    robot, arm = phantom_arm
    observer = JointObserver(arm, robot.encoder_resolution)
    step = 3.0 * observer.gate[0]
    ticks = observer.settings.reacquire_ticks
    for k in range(ticks + 1):  # a step past the gate, then a quantum further: alive
        q = arm.q0.copy()
        q[0] += step + robot.encoder_resolution[0] * (k > 0)
        observer.correct(q)
        observer.predict(np.zeros(arm.nu))
    assert observer.counts["reacquired"] == 1
    held = observer.counts["held"]
    x = observer.correct(np.full(arm.nu, np.nan))
    assert np.all(np.isfinite(x)) and observer.counts["held"] == held + 1
    observer.predict(np.zeros(arm.nu))
    assert np.all(np.isfinite(observer.x_prior))
