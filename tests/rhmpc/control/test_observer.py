"""The joint observer in the controller's library: its steps against the textbook filter, the
Kalman gain against the Riccati recursion, velocity from quantised encoders, and the innovation
gate's holds, reacquisitions and encoder faults on constructed readings.

The library runs on the linear model itself (no cancellation, so the torque that acts is the MPC
torque u the step returns), tracking the exact future of a heartbeat-like motion."""

import numpy as np
import pytest

from rhmpc.control.controller import Controller
from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.observer import JointObserver, ObserverSettings
from rhmpc.control.settings import MPCSettings
from rhmpc.robots import linearize, load_robot
from rhmpc.sim.loop.exact import ExactReference

TS = 0.5e-3
TICKS = 4000


@pytest.fixture(scope="module")
def phantom_arm():
    robot = load_robot("phantom")
    return robot, linearize(robot, Ts=TS)


def _motion(arm, ticks=TICKS):
    """A 1.2-Hz, 4-mm swing of the tool about its home position (centred truth) [m]."""
    t = np.arange(ticks + 200)[:, None] * TS
    return 2e-3 * np.sin(2 * np.pi * 1.2 * t) * np.array([1.0, 0.5, -0.5])


def library(robot, arm, settings=None):
    """The controller's library on the linear arm, its observer with ``settings``."""
    reference = ExactReference(_motion(arm), 50)
    reference.place(arm.y0)
    mpc = RecedingHorizonMPC(arm, MPCSettings(offset_correction=False))
    observer = JointObserver(arm, robot.encoder_resolution, settings)
    return Controller(mpc, reference, observer, None, arm.torque_limit)


def _loop(controller, arm, ticks, reading):
    """The linear model driven by the library's torque, the encoders giving ``reading(k, q)``;
    returns the estimates (ticks, 2n), the true velocities (ticks, n) and the torques."""
    x, est, vel, taus = np.zeros(arm.nx), [], [], []
    for k in range(ticks):
        tau = controller.step(k, reading(k, arm.q0 + x[: arm.nu]))
        est.append(controller.x_hat)
        vel.append(x[arm.nu:].copy())
        taus.append(tau)
        x = arm.A @ x + arm.B @ tau
    return np.array(est), np.array(vel), np.array(taus)


def test_steps_equal_the_textbook_filter(phantom_arm):
    """x̂ = x̂⁻ + L (q̃ − q0 − H x̂⁻), x̂⁻ = A x̂ + B u, with u the torque the step returned
    (readings 1 mrad apart: the innovation gate off)."""
    robot, arm = phantom_arm
    c = library(robot, arm, ObserverSettings(innovation_gate=0))
    L, n = c.observer.L, arm.nu
    rng = np.random.default_rng(3)
    x_prior = np.zeros(2 * n)
    for k in range(200):
        q = arm.q0 + rng.normal(size=n) * 1e-3
        u = c.step(k, q)
        x = x_prior + L @ (q - arm.q0 - x_prior[:n])
        np.testing.assert_allclose(c.x_hat, x, rtol=0, atol=1e-12)
        x_prior = arm.A @ x + arm.B @ u


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
    res = robot.encoder_resolution
    c = library(robot, arm)
    est, vel, _ = _loop(c, arm, TICKS, lambda k, q: np.rint(q / res) * res)
    err = np.sqrt(np.mean((est[1000:, arm.nu:] - vel[1000:]) ** 2, axis=0))
    assert np.ptp(vel[1000:], axis=0).min() > 0.01  # the joints move [rad/s]
    q = np.rint((arm.q0 + np.cumsum(vel, axis=0) * TS) / res) * res
    naive = np.diff(q, axis=0)[999:] / TS
    naive_err = np.sqrt(np.mean((naive - vel[1000:]) ** 2, axis=0))
    assert np.all(err < 0.2 * naive_err), (err, naive_err)
    assert c.encoder_counts == {"held": 0, "reacquired": 0}  # healthy readings all fused


def test_a_stuck_encoder_is_held_out_and_the_controller_brakes_after_the_timeout(phantom_arm):
    """A joint whose encoder stops while the loop moves it: the reading is held out, and after
    ``fault_timeout`` the MPC brakes (failure ``encoder_fault``, torque from ``brake``)."""
    robot, arm = phantom_arm
    res = robot.encoder_resolution
    c = library(robot, arm)
    stuck = {}

    def reading(k, q):
        q = np.rint(q / res) * res
        if k >= 300:  # joint 0 sticks at its reading of tick 300
            q[0] = stuck.setdefault("q", q[0])
        return q

    timeout = c.observer.timeout_ticks
    _loop(c, arm, 1500, reading)
    assert c.encoder_counts["held"] >= timeout and c.encoder_counts["reacquired"] == 0
    assert c.stats.failures.get("encoder_fault", 0) > 0
    assert c.stats.status == "encoder_fault" and c.stats.source == "brake"


def test_a_reading_that_moves_again_is_taken_again(phantom_arm):
    robot, arm = phantom_arm
    res = robot.encoder_resolution
    c = library(robot, arm)
    ticks = c.observer.settings.reacquire_ticks

    def reading(k, q):  # joint 0 is offset by 2 mrad from tick 50 (a disturbance, alive)
        return np.rint(q / res) * res + np.array([2e-3, 0.0, 0.0]) * (k >= 50)

    est, _, _ = _loop(c, arm, 50 + 2 * ticks + 10, reading)
    assert c.encoder_counts == {"held": ticks, "reacquired": 1}
    assert c.stats.failures.get("encoder_fault", 0) == 0
    assert np.all(np.isfinite(est))


def test_readings_that_are_not_finite_are_held_out(phantom_arm):
    """A reading with a NaN or an infinity is held out whole: the estimate is the prediction
    (at rest at q0 after a reset), and the step's torque stays finite."""
    robot, arm = phantom_arm
    c = library(robot, arm)
    for bad in (np.array([np.nan, 0.0, 0.0]), np.array([np.inf, 1e300, -np.inf])):
        c.reset()
        tau = c.step(0, arm.q0 + bad)
        assert np.all(c.x_hat == 0.0) and c.encoder_counts["held"] == 1
        assert np.all(np.isfinite(tau))


def test_a_reading_that_is_not_finite_is_held_out_after_a_reacquire_too(phantom_arm):
    """A hold that ends (the reading moved again) opens a grace in which readings are fused
    whatever the gate says: a NaN then (a reading that did not come) is still held out, and
    the estimate stays finite."""
    robot, arm = phantom_arm
    res = robot.encoder_resolution
    c = library(robot, arm)
    ticks = c.observer.settings.reacquire_ticks
    missing = 50 + ticks + 3  # within the grace after the reacquisition

    def reading(k, q):  # joint 0 offset by 2 mrad from tick 50 (alive), one reading lost
        q = np.rint(q / res) * res + np.array([2e-3, 0.0, 0.0]) * (k >= 50)
        return np.full_like(q, np.nan) if k == missing else q

    est, _, taus = _loop(c, arm, missing + 2, reading)
    assert c.encoder_counts == {"held": ticks + 1, "reacquired": 1}
    assert np.all(np.isfinite(est)) and np.all(np.isfinite(taus))


def _filter(x_prior, L, n, q0, readings, inputs, A, B, tick):
    """The textbook filter from ``x_prior`` at tick 0 to the estimate of ``tick``, fusing the
    readings of the ticks in ``readings`` (tick → q̃) and none at the others."""
    x = x_prior
    for t in range(tick + 1):
        if t in readings:
            x = x + L @ (readings[t] - q0 - x[:n])
        if t < tick:
            x = A @ x + B @ inputs[t]
    return x


def test_a_late_reading_is_fused_into_its_tick_and_carried_forward(phantom_arm):
    """Readings that come 0 to 6 ticks after their instant (seeded), the step given the newest
    that has come (the others skipped, a tick with none new given NaN): at every tick the
    estimate is the textbook filter's that fused those readings at their own ticks and none
    at the ticks between, with the torques the steps returned (the recalculation of Larsen
    et al. 1998)."""
    robot, arm = phantom_arm
    c = library(robot, arm, ObserverSettings(innovation_gate=0))
    L, n, rng = c.observer.L, arm.nu, np.random.default_rng(11)
    ticks = 240
    q = arm.q0 + rng.normal(size=(ticks, n)) * 1e-3
    came = np.arange(ticks) + rng.integers(0, 7, size=ticks)  # the tick each reading comes on
    fused, inputs, last, late = {}, [], -1, 0
    for k in range(ticks):
        newest = max((m for m in range(last + 1, k + 1) if came[m] <= k), default=None)
        if newest is None:
            inputs.append(c.step(k, np.full(n, np.nan)))
        else:
            inputs.append(c.step(k, q[newest], delay=k - newest))
            fused[newest], last, late = q[newest], newest, late + (newest < k)
        expected = _filter(np.zeros(2 * n), L, n, arm.q0, fused, inputs, arm.A, arm.B, k)
        np.testing.assert_allclose(c.x_hat, expected, rtol=0, atol=1e-12, err_msg=f"tick {k}")
    assert late > ticks // 5 and len(fused) < ticks  # many came late, some were skipped


def test_a_reading_too_late_or_superseded_is_no_reading(phantom_arm):
    """A reading not newer than the last one taken, or more than ``max_delay`` late, leaves the
    estimate at the prediction, as a reading that did not come (held out, counted)."""
    robot, arm = phantom_arm
    c = library(robot, arm, ObserverSettings(innovation_gate=0, max_delay=2e-3))  # 4 ticks
    for k in range(8):
        tau = c.step(k, arm.q0)
    for k in (8, 9):
        tau = c.step(k, np.full(arm.nu, np.nan))
    q = arm.q0 + 1e-3
    held = c.encoder_counts["held"]
    tau = c.step(10, q, delay=2)  # of tick 8: fused
    assert c.encoder_counts["held"] == held
    for k, delay in ((11, 3), (12, 5)):  # tick 8 again; tick 7, older and past the window
        prediction = arm.A @ c.x_hat + arm.B @ tau
        tau = c.step(k, q, delay=delay)
        np.testing.assert_allclose(c.x_hat, prediction, rtol=0, atol=1e-15, err_msg=f"{k}")
    assert c.encoder_counts["held"] == held + 2
    c.step(13, q, delay=4)  # of tick 9: newer than 8, within the window
    assert c.encoder_counts["held"] == held + 2
