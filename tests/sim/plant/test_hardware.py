"""The hardware-like plant, each effect against an independent reference."""

import math

import numpy as np
import pinocchio as pin
import pytest

from rhmpc.control.cancellation import ModelMismatch, NonlinearityCancellation
from rhmpc.control.controller import Controller
from rhmpc.control.mpc import RecedingHorizonMPC
from rhmpc.control.observer import JointObserver
from rhmpc.robots import Robot, linearize
from rhmpc.sim.loop.exact import ExactReference
from rhmpc.sim.plant import PlantSettings, make_plant
from rhmpc.sim.plant.hardware import HardwarePlant, LinearPlant, cable_stiffness
from tests.sim.plant import reference, rig

TS = 0.5e-3
J_LINK, J_ROTOR, ETA, KT = 2.0e-3, 1.5e-4, 10.0, 0.0234
#: Every effect off: the reference against which one effect at a time is switched on.
BARE = dict(delay_ticks=0, current_time_constant=0.0, dac_bits=0, dac_range=100.0,
            stiction_ratio=1.0, torque_constant=KT, friction_smoothing=1e-3)


def drum(coulomb: float = 0.0) -> Robot:
    """One link turning about the vertical (no gravity torque) with inertia J_LINK, driven by a
    motor of reflected rotor inertia J_ROTOR through ratio ETA."""
    model = pin.Model()
    jid = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "drum")
    model.appendBodyToJoint(jid, pin.Inertia(0.1, np.zeros(3), np.diag([1e-4, 1e-4, J_LINK])),
                            pin.SE3.Identity())
    model.addFrame(pin.Frame("tip", jid, 0, pin.SE3(np.eye(3), np.array([0.1, 0, 0])),
                             pin.FrameType.OP_FRAME))
    model.armature[:] = J_ROTOR
    model.friction[:] = coulomb
    model.lowerPositionLimit[:], model.upperPositionLimit[:] = -10.0, 10.0
    model.velocityLimit[:] = 10.0
    return Robot("drum", model, "tip", np.zeros(1), np.array([5.0]),
                 encoder_resolution=np.array([2 * np.pi / (4096 * ETA)]),
                 gear_ratio=np.array([ETA]), rotor_inertia=np.array([J_ROTOR]))


def tick_of(robot: Robot, **settings) -> HardwarePlant:
    steps = 20 if settings.get("cable_resonance") else 4
    hardware = PlantSettings(**{**BARE, "substeps": steps, **settings})
    return HardwarePlant(robot, TS, hardware)


def drive(plant: HardwarePlant, torques) -> np.ndarray:
    """Apply torques tick by tick (the drum has no gravity: nothing to cancel); the link
    angles."""
    out = []
    for u in torques:
        plant.encoders()
        plant.step(np.atleast_1d(u))
        out.append(plant.q_arm[0])
    return np.array(out)


def hold_home(robot: Robot, arm, plant, ticks: int,
              mismatch: ModelMismatch | None = None) -> list:
    """The controller (its library: observer, MPC holding the home point, cancellation) around
    ``plant``: the arm's states after each tick."""
    reference = ExactReference(np.zeros((ticks + 60, 3)), 50)
    reference.place(arm.y0)
    controller = Controller(RecedingHorizonMPC(arm), reference,
                            JointObserver(arm, robot.encoder_resolution),
                            NonlinearityCancellation(robot, mismatch), robot.torque_limit)
    states = []
    for i in range(ticks):
        plant.step(controller.step(i, plant.encoders()))
        states.append(np.r_[plant.q_arm, plant.v, plant.theta_r, plant.current])
    return states


def test_delay_shifts_the_torque_by_one_tick_exactly():
    """One tick of I/O delay is the undelayed plant fed the torques one tick later."""
    u = 0.05 * np.sin(np.arange(200) / 7.0)
    delayed = drive(tick_of(drum(), delay_ticks=1), u)
    shifted = drive(tick_of(drum()), np.r_[0.0, u[:-1]])
    np.testing.assert_array_equal(delayed, shifted)


def test_dac_rounds_to_its_step_and_clips():
    """τ_e = 0: the current is the DAC's output, i* rounded to 2 I_max / 2^b and clipped."""
    step = 2 * 5.5 / 4096  # 12 bits over ±5.5 A
    for wanted, out in ((0.4 * step, 0.0), (0.6 * step, step), (-1.49 * step, -step),
                        (2.5 * step, 2 * step), (7.0, 5.5), (-7.0, -5.5)):
        plant = tick_of(drum(), dac_bits=12, dac_range=5.5)
        plant.step(np.array([wanted * ETA * KT]))
        assert plant.current[0] == pytest.approx(out, rel=1e-12, abs=1e-15)
        assert plant.saturated == (abs(wanted) > 5.5)
    plant = tick_of(drum(), dac_bits=0, dac_range=5.5)
    plant.step(np.array([0.4 * step * ETA * KT]))
    assert plant.current[0] == pytest.approx(0.4 * step, rel=1e-12)


def test_current_and_motion_follow_the_first_order_lag():
    """A current step through τ_e = L/R: i(t) = i*(1 − e^(−t/τ_e)) at every tick, and the free
    drum turns by θ(t) = (η K_t i*/J)(t²/2 − τ_e t + τ_e²(1 − e^(−t/τ_e))): to 2e-8 rad (3 nm
    at 0.17 m; the steps take the current's exact mean, what remains is its shape within the
    first step)."""
    tau_e = 0.238e-3 / 2.18
    tick = tick_of(drum(), current_time_constant=tau_e)
    torque = 0.02
    angles = drive(tick, [torque] * 40)
    t = TS * np.arange(1, 41)
    i_star = torque / (ETA * KT)
    assert tick.current[0] == pytest.approx(i_star * (1 - math.exp(-40 * TS / tau_e)), rel=1e-12)
    ref = torque / (J_LINK + J_ROTOR) * (t**2 / 2 - tau_e * t + tau_e**2 * (1 - np.exp(-t / tau_e)))
    np.testing.assert_allclose(angles, ref, rtol=0, atol=2e-8)


def test_cable_resonance_is_the_two_mass_frequency():
    """Free oscillation of rotor against link through the cable: f = √(k (J1 + J2)/(J1 J2))/2π
    with the k the settings derive (to 0.5 %), for 40 and 150 Hz."""
    for f_r in (40.0, 150.0):
        tick = tick_of(drum(), cable_resonance=f_r, cable_damping_ratio=0.0)
        k = tick.k[0]
        assert k == pytest.approx(cable_stiffness(f_r, np.array([J_ROTOR]), np.array([J_LINK]),
                                                  0.0)[0][0])
        tick.theta_r = np.array([1e-3])  # a twisted cable, released
        twist = []
        for _ in range(400):
            tick.step(np.zeros(1))
            twist.append(tick.theta_r[0] - tick.q_arm[0])
        crossings = np.flatnonzero(np.diff(np.sign(twist)) != 0)
        measured = (len(crossings) - 1) / (2 * TS * (crossings[-1] - crossings[0]))
        analytic = math.sqrt(k * (J_ROTOR + J_LINK) / (J_ROTOR * J_LINK)) / (2 * math.pi)
        assert measured == pytest.approx(analytic, rel=5e-3)
        assert analytic == pytest.approx(f_r, rel=1e-12)


def test_encoders_count_the_motor_through_the_cable():
    tick = tick_of(drum(), cable_resonance=60.0, error_from="encoders")
    tick.theta_r = np.array([0.01])
    res = tick.robot.encoder_resolution[0]
    assert tick.encoders()[0] == pytest.approx(res * round(0.01 / res), abs=1e-15)
    assert tick.q[0] == tick.encoders()[0] and tick.q_arm[0] == 0.0


def test_friction_is_the_stribeck_law():
    """The drum's deceleration over a tick of 1 ns at rate ω, times its inertia, is the
    friction law of ``reference.friction`` (peaking at rest: 1.25 F_c at 0.1 mrad/s)."""
    ts = 1e-9
    for w in (1e-4, 3e-3, 0.02, 1.0, -1.0):
        plant = HardwarePlant(drum(coulomb=0.01), ts, PlantSettings(
            **{**BARE, "stiction_ratio": 1.25, "substeps": 1}))
        plant.v = np.array([w])
        plant.step(np.zeros(1))
        seen = -(J_LINK + J_ROTOR) * (plant.v[0] - w) / ts
        assert seen == pytest.approx(reference.friction(w, 0.01, 0.0, 1.25, 0.01, 1e-3),
                                     rel=1e-5)
    assert reference.friction(1e-4, 0.01, 0.0, 1.25, 0.01, 1e-6) == pytest.approx(0.0125,
                                                                                   rel=1e-4)


def test_stiction_holds_a_torque_below_the_peak():
    """A drum with 10 mN·m Coulomb friction barely creeps under 11 mN·m (below the 12.5-mN·m
    stiction peak) and breaks away under 14 mN·m."""
    held = drive(tick_of(drum(coulomb=0.01), stiction_ratio=1.25), [0.011] * 400)
    moved = drive(tick_of(drum(coulomb=0.01), stiction_ratio=1.25), [0.014] * 400)
    assert abs(held[-1]) < 0.1 * abs(moved[-1])


@pytest.mark.parametrize("bad", [{"delay_ticks": -1}, {"dac_bits": 1.5}, {"dac_range": -1.0},
                                 {"dac_bits": 12}, {"torque_constant": 0.0234}, {"kind": "ideal"},
                                 {"substeps": -1}, {"friction_smoothing": 0.0},
                                 {"stiction_ratio": 0.5}, {"cable_resonance": float("nan")},
                                 {"error_from": "tip"}])
def test_bad_settings_are_one_line_errors(bad):
    with pytest.raises(ValueError) as err:
        PlantSettings(**bad)
    assert "\n" not in str(err.value)


def test_hardware_plant_needs_drives(arm):
    from rhmpc.robots import load_robot

    ur5 = load_robot("ur5")
    with pytest.raises(ValueError, match="needs the robot's drives"):
        make_plant(ur5, linearize(ur5), TS, rig())


def test_phantom_rests_at_home_under_its_own_cancellation(phantom, arm):
    """Default hardware plant (delay, DAC, lag, stiction), the controller's model the plant's,
    its MPC holding the home point: the tip stays within 0.02 mm over 1 s (what is left: the
    DAC's rounding of the gravity torque, creeping against the smoothed friction)."""
    plant = make_plant(phantom, arm, TS, rig())
    assert isinstance(plant, HardwarePlant)
    states = hold_home(phantom, arm, plant, 2000)
    drift = max(np.linalg.norm(phantom.ee_position(x[:3]) - phantom.ee_position(phantom.q0))
                for x in states)
    assert drift < 2e-5


def test_linear_plant_is_the_mpc_model(phantom, arm):
    plant = make_plant(phantom, arm, TS, PlantSettings(kind="linear"))
    assert isinstance(plant, LinearPlant)
    rng = np.random.default_rng(0)
    x = np.zeros(6)
    for _ in range(50):
        u = rng.normal(size=3) * 0.05
        plant.step(u)
        x = arm.A @ x + arm.B @ u
    np.testing.assert_allclose(plant.q, arm.q0 + x[:3], atol=1e-15)
