"""The plant's dynamics kernel (sim/plant/chain.c) against Pinocchio and against the plain
references of ``reference.py``: the rigid-body functions, one tick of each plant, a closed loop."""

import numpy as np
import pinocchio as pin
import pytest

from rhmpc.robots.model import forward_dynamics
from rhmpc.sim.plant import ArmPlant, HardwarePlant, PlantSettings, kernel
from tests.sim.plant import reference, rig

TS = 0.5e-3


@pytest.fixture(scope="module")
def chain(phantom):
    return kernel.Chain(phantom.model)


def random_states(n=300, seed=0):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield (rng.uniform(-3, 3, 3), rng.uniform(-8, 8, 3), rng.uniform(-2, 2, 3),
               rng.uniform(-80, 80, 3))


def test_aba_and_rnea_match_pinocchio(phantom, chain):
    model, data = phantom.model, phantom.create_data()
    worst = {"aba": 0.0, "rnea": 0.0}
    for q, v, tau, a in random_states():
        ref = forward_dynamics(model, data, q, v, tau)
        worst["aba"] = max(worst["aba"], np.abs(chain.forward_dynamics(q, v, tau) - ref).max()
                           / np.abs(ref).max())
        ref = pin.rnea(model, data, q, v, a)
        worst["rnea"] = max(worst["rnea"], np.abs(chain.rnea(q, v, a) - ref).max()
                            / np.abs(ref).max())
    assert worst["aba"] < 1e-14 and worst["rnea"] < 1e-14  # relative: rounding

def test_mass_matrix_is_pinocchios_crba_and_aba_is_its_solve(phantom, chain):
    """M(q) by the composite-rigid-body algorithm over the mimic bodies against ``pin.crba``, and
    the forward dynamics against M⁻¹(τ − h) with Pinocchio's M and h."""
    model, data = phantom.model, phantom.create_data()
    worst_M, worst_fd = 0.0, 0.0
    for q, v, tau, _ in random_states(100, seed=2):
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        worst_M = max(worst_M, np.abs(chain.mass(q) - M).max() / np.abs(M).max())
        h = pin.rnea(model, data, q, v, np.zeros(3))
        ref = np.linalg.solve(M, tau - h)
        qdd = chain.forward_dynamics(q, v, tau)
        worst_fd = max(worst_fd, np.abs(qdd - ref).max() / np.abs(ref).max())
    assert worst_M < 1e-14 and worst_fd < 1e-13  # relative: rounding


def rotated_tree(rng: np.random.Generator) -> pin.Model:
    """Four revolute joints of every kind the chain compiles (RX, RY, RZ, an unaligned axis),
    rotated placements, a branch, random inertias and armature: the general transforms."""
    model = pin.Model()
    kinds = [pin.JointModelRX(), pin.JointModelRevoluteUnaligned(*rng.normal(size=3)),
             pin.JointModelRZ(), pin.JointModelRY()]
    for i, (kind, parent) in enumerate(zip(kinds, (0, 1, 2, 2), strict=True)):
        R = pin.exp3(rng.normal(size=3))
        j = model.addJoint(parent, kind, pin.SE3(R, rng.normal(scale=0.2, size=3)), f"j{i}")
        A = rng.normal(size=(3, 3))
        inertia = pin.Inertia(rng.uniform(0.1, 2.0), rng.normal(scale=0.1, size=3),
                              A @ A.T * 0.01 + np.eye(3) * 1e-3)
        model.appendBodyToJoint(j, inertia, pin.SE3.Identity())
    model.armature = rng.uniform(0.0, 0.01, model.nv)
    return model


def test_general_placements_and_axes_match_pinocchio():
    """RNEA, M and ABA on rotated placements and an unaligned axis (not the PHANToM's
    identity placements about coordinate axes) against ``pin.rnea``, ``pin.crba``, ``pin.aba``."""
    rng = np.random.default_rng(7)
    model = rotated_tree(rng)
    chain = kernel.Chain(model)
    data = model.createData()
    worst = {"rnea": 0.0, "mass": 0.0, "aba": 0.0}
    for _ in range(100):
        q, v, a, tau = (rng.uniform(-3, 3, 4) for _ in range(4))
        ref = pin.rnea(model, data, q, v, a)
        worst["rnea"] = max(worst["rnea"], np.abs(chain.rnea(q, v, a) - ref).max()
                            / np.abs(ref).max())
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        worst["mass"] = max(worst["mass"], np.abs(chain.mass(q) - M).max() / np.abs(M).max())
        ref = pin.aba(model, data, q, v, tau)
        worst["aba"] = max(worst["aba"], np.abs(chain.forward_dynamics(q, v, tau) - ref).max()
                           / np.abs(ref).max())
    assert max(worst.values()) < 1e-13, worst  # relative: rounding



def test_ideal_tick_is_the_plain_midpoint_on_pinocchio(phantom):
    """One tick of :class:`ArmPlant` (clipping, friction on the motors' rates, two midpoint
    steps) against ``reference.ideal_tick``, from random states, some torques past the limits."""
    plant = ArmPlant(phantom, TS)
    worst = 0.0
    for q, v, tau, _ in random_states(100, seed=1):
        plant.q, plant.v = q, v
        plant.step(tau)
        ref_q, ref_v = reference.ideal_tick(phantom, q, v, tau, TS)
        worst = max(worst, np.abs(np.r_[plant.q - ref_q, plant.v - ref_v]).max())
    assert worst < 1e-11  # rad, rad/s: rounding (rates up to 8 rad/s, accelerations 1e4)


@pytest.mark.parametrize("cables", [0.0, 80.0])
def test_hardware_tick_is_the_plain_one_on_pinocchio(phantom, cables):
    """One tick of :class:`HardwarePlant` without delay (DAC, lag, Stribeck friction, rigid or
    with cables) against ``reference.hardware_tick``, from random states and currents."""
    settings = rig(delay_ticks=0, cable_resonance=cables, substeps=20 if cables else 4)
    plant = HardwarePlant(phantom, TS, settings)
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(30):
        state = [phantom.q0 + rng.uniform(-0.3, 0.3, 3), rng.uniform(-2, 2, 3),
                 rng.uniform(-1e-3, 1e-3, 3), rng.uniform(-2, 2, 3)]
        if not cables:
            state[2:] = [np.zeros(3), np.zeros(3)]
        current, tau = rng.uniform(-3, 3, 3), rng.uniform(-1, 1, 3)
        plant.q_arm, plant.v, plant.theta_r, plant.omega_r = state
        plant._drive.current[:] = current
        plant.step(tau)
        ref, ref_current = reference.hardware_tick(phantom, settings, state, current, tau)
        got = [plant.q_arm, plant.v, plant.theta_r, plant.omega_r]
        scale = [max(1.0, np.abs(r).max()) for r in ref]
        worst = max(worst, *(np.abs(g - r).max() / s
                             for g, r, s in zip(got, ref, scale, strict=True)),
                    np.abs(plant.current - ref_current).max())
    assert worst < 1e-11


@pytest.mark.slow
def test_a_closed_loop_run_matches_one_on_a_pinocchio_plant(monkeypatch):
    """A whole run (encoders, observer, cancellation with its own model) on the kernel's plant
    against the same run on ``reference.ideal_tick``: the metrics agree to 1e-6 relative (the
    states part by rounding: a Cholesky solve in C against LAPACK's)."""
    from rhmpc.experiment import RunConfig, assembly, run_experiment
    from rhmpc.sim.loop import LoopSettings

    class PinocchioPlant(ArmPlant):
        def step(self, tau):
            self.q, self.v = reference.ideal_tick(self.robot, self.q, self.v, tau, self.Ts)

    config = RunConfig(loop=LoopSettings(duration=4.0, settling=4.0 / 3), seed=1)
    doc = run_experiment(config)[1]
    monkeypatch.setattr(assembly, "make_plant", lambda robot, arm, Ts, *_: PinocchioPlant(
        robot, Ts))
    ref = run_experiment(config)[1]
    for key in ("rms_error_mm", "max_error_mm", "rms_effort_mNm", "rms_total_torque_mNm"):
        np.testing.assert_allclose(doc[key], ref[key], rtol=1e-6, err_msg=key)
    assert doc["saturated_ticks"] == ref["saturated_ticks"]


def test_what_the_kernel_cannot_take_is_a_one_line_error(phantom, monkeypatch):
    model = pin.Model()  # a prismatic joint: not compiled
    model.addJoint(0, pin.JointModelPX(), pin.SE3.Identity(), "slider")
    with pytest.raises(ValueError, match="revolute"):
        kernel.Chain(model)
    monkeypatch.setattr(kernel, "_library", lambda: (_ for _ in ()).throw(
        ValueError("the plant's dynamics kernel (sim/plant/chain.c) cannot be built: no C "
                   "compiler (cc/gcc) on PATH")))
    with pytest.raises(ValueError, match="compiler") as err:
        ArmPlant(phantom, TS, PlantSettings())
    assert "\n" not in str(err.value)
