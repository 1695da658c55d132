"""The ideal plant against a fine Runge–Kutta reference, energy, clipping; the cancellation."""

import numpy as np
import pinocchio as pin
import pytest

from rhmpc.control.cancellation import ModelMismatch, NonlinearityCancellation
from rhmpc.robots import load_robot
from rhmpc.sim.plant import ArmPlant, PlantSettings
from tests.sim.plant import reference

TS = 0.5e-3
REACH = 0.4  # [m] bound on the lever from any joint axis to the PHANToM tip


def rk4_tick(robot, q, v, tau, steps=400):
    """A plain reference: classical Runge–Kutta, ``steps`` steps over the tick, on Pinocchio."""
    data, h = robot.create_data(), TS / steps
    tau = np.clip(tau, -robot.torque_limit, robot.torque_limit)

    def f(x):
        return np.r_[x[3:], reference.ideal_rates(robot, data, x[:3], x[3:], tau, 5e-3)]

    x = np.r_[q, v]
    for _ in range(steps):
        k1 = f(x)
        k2 = f(x + 0.5 * h * k1)
        k3 = f(x + 0.5 * h * k2)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + f(x + h * k3))
    return x


@pytest.mark.slow
def test_default_integrator_local_error_against_fine_rk4(phantom):
    rng = np.random.default_rng(5)
    plant = ArmPlant(phantom, TS)
    for _ in range(30):
        q, v = phantom.q0 + rng.normal(size=3) * 0.2, rng.normal(size=3) * 0.3
        tau = rng.normal(size=3) * 0.3
        ref = rk4_tick(phantom, q, v, tau)
        plant.q, plant.v = q, v
        plant.step(tau)
        assert np.abs(plant.q - ref[:3]).max() * REACH < 0.5e-6  # [m] at the tip, per tick
        assert np.abs(plant.v - ref[3:]).max() < 5e-3  # [rad/s]


def total_energy(robot, data, q, v):
    """½ q̇ᵀ M(q) q̇ − Σ m_i g·c_i(q) (Pinocchio's energy functions take no mimic joints)."""
    kinetic = 0.5 * v @ robot.mass_matrix(q) @ v
    pin.forwardKinematics(robot.model, data, q)
    gravity = robot.model.gravity.linear
    potential = -sum(inertia.mass * gravity @ (data.oMi[i] * inertia.lever)
                     for i, inertia in enumerate(robot.model.inertias) if i > 0)
    return kinetic + potential


def test_energy_is_conserved_without_friction_and_torque(phantom):
    """A free swing under gravity (no damping, no friction, τ = 0) keeps its energy."""
    robot = load_robot("phantom")
    robot.model.damping[:] = 0.0
    robot.model.friction[:] = 0.0
    plant = ArmPlant(robot, TS, PlantSettings())
    plant.reset(q=robot.q0 + np.array([0.3, 0.4, -0.3]), v=np.array([0.5, -0.2, 0.3]))
    data = robot.create_data()
    e0 = total_energy(robot, data, plant.q, plant.v)
    energies = []
    for _ in range(2000):  # 1 s
        plant.step(np.zeros(3))
        energies.append(total_energy(robot, data, plant.q, plant.v))
    drift = np.abs(np.array(energies) - e0).max()
    assert drift < 1e-6 * max(abs(e0), 1e-3)  # relative drift over 1 s
    assert np.ptp(plant.q) > 0  # it did move


def test_torque_is_clipped_to_actuator_limits(phantom):
    plant, clipped = ArmPlant(phantom, TS), ArmPlant(phantom, TS)
    plant.step(np.array([10.0, -10.0, 0.0]))
    assert plant.saturated
    clipped.step(np.array([phantom.torque_limit[0], -phantom.torque_limit[1], 0.0]))
    assert not clipped.saturated
    np.testing.assert_array_equal(plant.v, clipped.v)


def model_torque(cancellation, q, v):
    """ĝ + Ĉq̇ + f̂ of the controller's model (its masses, friction and motor map), by Pinocchio:
    RNEA at zero acceleration plus Sᵀ (D̂ ω + F̂_c tanh(ω / v_s)), ω = S q̇ [N·m]."""
    S = np.asarray(cancellation.motor_map, dtype=float)
    w = S @ v
    friction = (cancellation.damping * w
                + cancellation.coulomb_friction * np.tanh(w / cancellation.stiction_velocity))
    model = cancellation.model
    return pin.rnea(model, model.createData(), q, v, np.zeros_like(v)) + S.T @ friction


def test_exact_cancellation_holds_the_arm_still(phantom):
    """With the controller's model equal to the plant, τ = ĝ + Ĉq̇ + f̂ leaves q̈ = 0 at rest."""
    plant = ArmPlant(phantom, TS)
    cancel = NonlinearityCancellation(phantom)
    for _ in range(200):
        plant.step(model_torque(cancel, plant.q, plant.v))
    np.testing.assert_allclose(plant.q, phantom.q0, atol=1e-9)


def test_mass_mismatch_scales_gravity_compensation(phantom):
    q = phantom.q0 + np.array([0.0, 0.3, -0.2])
    exact = model_torque(NonlinearityCancellation(phantom), q, np.zeros(3))
    heavy = model_torque(NonlinearityCancellation(phantom, ModelMismatch(mass_scale=1.2)), q,
                         np.zeros(3))
    np.testing.assert_allclose(heavy, 1.2 * exact, rtol=1e-12, atol=1e-15)
    with pytest.raises(ValueError, match="mass_scale"):
        ModelMismatch(mass_scale=float("nan"))


def test_bad_plant_settings_raise():
    with pytest.raises(ValueError, match="valid: arm, linear"):
        PlantSettings(kind="rigid")
    with pytest.raises(ValueError, match="substeps"):
        PlantSettings(substeps=-1)
