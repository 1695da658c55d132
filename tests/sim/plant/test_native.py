"""The compiled chain dynamics against Pinocchio: functions, one tick, a whole closed-loop run."""

import numpy as np
import pinocchio as pin
import pytest

from robots.model import forward_dynamics
from sim.plant import ArmPlant, PlantSettings, native

TS = 0.5e-3


@pytest.fixture(scope="module")
def chain(phantom):
    c = native.load_chain(phantom.model, phantom.damping, phantom.coulomb_friction,
                          motor_map=phantom.motor_map)
    if c is None:
        pytest.skip(f"no compiled chain: {native.unavailable_reason}")
    return c


def random_states(n=300, seed=0):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield (rng.uniform(-3, 3, 3), rng.uniform(-8, 8, 3), rng.uniform(-2, 2, 3),
               rng.uniform(-80, 80, 3))


def test_aba_rnea_and_end_point_match_pinocchio(phantom, chain):
    model, data = phantom.model, phantom.create_data()
    frame = model.frames[phantom.ee_frame_id]
    worst = {"aba": 0.0, "rnea": 0.0, "point": 0.0}
    for q, v, tau, a in random_states():
        ref = forward_dynamics(model, data, q, v, tau)
        worst["aba"] = max(worst["aba"], np.abs(chain.forward_dynamics(q, v, tau) - ref).max()
                           / np.abs(ref).max())
        ref = pin.rnea(model, data, q, v, a)
        worst["rnea"] = max(worst["rnea"], np.abs(chain.rnea(q, v, a) - ref).max()
                            / np.abs(ref).max())
        pin.forwardKinematics(model, data, q)
        ref = pin.updateFramePlacement(model, data, phantom.ee_frame_id).translation
        got = chain.points(q, frame.parentJoint, frame.placement.translation)[0]
        worst["point"] = max(worst["point"], np.abs(got - ref).max())
    # measured 6e-16, 1e-15 (relative) and 6e-17 m: rounding; bounds with a 10x margin
    assert worst["aba"] < 1e-14 and worst["rnea"] < 1e-14 and worst["point"] < 1e-15



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
    assert worst_M < 1e-14 and worst_fd < 1e-13  # measured 6e-16 and 1.7e-15: rounding


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
    chain = native.load_chain(model)
    if chain is None:
        pytest.skip(f"no compiled chain: {native.unavailable_reason}")
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
    assert max(worst.values()) < 1e-13, worst  # rounding: measured 5e-15, 5e-16, 1.7e-15

def test_native_tick_is_the_pinocchio_tick(phantom, chain):
    ref = ArmPlant(phantom, TS, PlantSettings(dynamics="pinocchio"))
    got = ArmPlant(phantom, TS, PlantSettings(dynamics="native"))
    assert (ref.dynamics, got.dynamics) == ("pinocchio", "native")
    worst = 0.0
    for q, v, tau, _ in random_states(100, seed=1):
        for plant in (ref, got):
            plant.q, plant.v = q.copy(), v.copy()
            plant.step(tau)
        worst = max(worst, np.abs(np.r_[got.q - ref.q, got.v - ref.v]).max())
    assert worst < 1e-13  # measured ≈ 1e-15 (rad, rad/s): the same arithmetic up to rounding


@pytest.mark.parametrize("duration, changes", [
    (6.0, {}),  # generalized predictor, sonomicrometry, encoders
    (3.0, {"predictor": "exact", "sensor": "ideal", "ground_truth": "true",
           "mismatch.mass_scale": 0.8, "mismatch.friction_scale": 0.5}),
])
@pytest.mark.slow
def test_a_closed_loop_run_on_the_native_tick_matches_pinocchio(chain, duration, changes):
    """A whole run with the compiled tick (encoders, observer, cancellation with its own
    model, plant) against the Python tick on Pinocchio: the metrics agree to 1e-6 relative
    (measured 9e-8: max_error_mm 5.5e-8 mm apart): with the exact screening cascade the MPC
    answers a 1e-15 state difference in full rather than through OSQP's warm-started iterate,
    and the two runs' states part by rounding differences (the mimic linkage's dynamics are a
    Cholesky solve in C, LAPACK's in Pinocchio), now and then one encoder count apart. With
    the mismatch, 80 % of the elbow's negative gravity stiffness cancelled and half the
    friction, the loop amplifies them: the end-points part by 1e-12 m at 0.9 s, 1e-9 m at
    4 s and 1e-6 m at 5.1 s (measured), so that run lasts 3 s."""
    from rhmpc.experiment import RunConfig, run_experiment
    from sim.loop import LoopSettings

    loop = LoopSettings(duration=duration, settling=duration / 3)
    base = RunConfig(loop=loop, seed=1).replace(**changes)
    docs = [run_experiment(base.replace(**{"plant.dynamics": d}))[1]
            for d in ("pinocchio", "native")]
    for key in ("rms_error_mm", "max_error_mm", "rms_effort_mNm", "rms_total_torque_mNm"):
        np.testing.assert_allclose(docs[1][key], docs[0][key], rtol=1e-6, err_msg=key)
    assert docs[0]["predictor_counts"] == docs[1]["predictor_counts"]
    assert docs[0]["saturated_ticks"] == docs[1]["saturated_ticks"]


def test_unsupported_models_and_forced_native_say_why(phantom, monkeypatch):
    model = pin.Model()  # a prismatic joint: not compiled
    model.addJoint(0, pin.JointModelPX(), pin.SE3.Identity(), "slider")
    assert native.load_chain(model) is None
    assert "revolute" in native.unavailable_reason
    monkeypatch.setattr(native, "_tried", True)
    monkeypatch.setattr(native, "_library", None)
    monkeypatch.setattr(native, "unavailable_reason", "no C compiler (cc/gcc) on PATH")
    plant = ArmPlant(phantom, TS)  # auto: falls back to Pinocchio and says why
    assert plant.dynamics == "pinocchio" and "compiler" in plant.dynamics_note
    with pytest.raises(ValueError, match="compiler"):
        ArmPlant(phantom, TS, PlantSettings(dynamics="native"))
