"""The PHANToM model against its sources' own equations (mahilab/Phantom PhantomModel.cpp/.hpp).

The source's coordinates: q2_src (upper arm, up positive), q3_src (the forearm's absolute angle,
0 = vertical down); the model's: q2 = −q2_src, q3 = 90° − q3_src − q2 (relative elbow).
"""

import numpy as np
import pinocchio as pin
import pytest

from rhmpc.robots import load_robot
from rhmpc.robots.model import forward_dynamics
from rhmpc.robots.registry import urdf_path

G = 9.80665
#: ∂(q2_src, q3_src)/∂(q2, q3), and the full map on (q1, q2, q3)
T = np.array([[-1.0, 0.0], [-1.0, -1.0]])
T_FULL = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, -1.0, -1.0]])


def to_source(q):
    return -q[1], np.pi / 2 - (q[1] + q[2])


def gravity_solidworks(q2, q3):
    """PhantomModel.cpp G() with the PhantomModel.hpp constants (SolidWorks set)."""
    m_a, m_c, m_be, m_df, l1, l3 = 0.026220, 0.026146, 0.267840, 0.215420, 0.209550, 0.031750
    a, c = (0.00002423, -0.05237892), (0.0, 0.10477739)
    be, df = (-0.03518875, -0.0000628), (-0.05153541, 0.00060903)
    s2, c2, s3, c3 = np.sin(q2), np.cos(q2), np.sin(q3), np.cos(q3)
    g2 = G * (-be[1] * m_be * s2 + c[0] * m_c * s2 + l1 * m_a * c2 + be[0] * m_be * c2
              + c[1] * m_c * c2)
    g3 = G * (-a[1] * m_a * s3 + df[0] * m_df * s3 + l3 * m_c * s3 + a[0] * m_a * c3
              + df[1] * m_df * c3)
    return np.array([g2, g3])


CAV = dict(ma=0.0202, mc=0.0249, mbe=0.2359, mdf=0.1906, l1=0.215, l2=0.170, l3=0.0325,
           l5=-0.0368, l6=0.0527)


def gravity_cavusoglu(q2, q3):
    """PhantomModel.cpp step_dynamics_cavusoglu ``_G``."""
    p = CAV
    return 0.5 * G * np.array([
        (2 * p["l1"] * p["ma"] + 2 * p["l5"] * p["mbe"] + p["l1"] * p["mc"]) * np.cos(q2),
        (p["l2"] * p["ma"] + 2 * p["l3"] * p["mc"] - 2 * p["l6"] * p["mdf"]) * np.sin(q3)])


def mass_cavusoglu(q2, q3):
    """PhantomModel.cpp step_dynamics_cavusoglu ``_M`` (no rotors), source coordinates."""
    p = CAV
    ma, mc, L1, L2, L3 = p["ma"], p["mc"], p["l1"], p["l2"], p["l3"]
    Iayy, Iazz, Iaxx = 0.001843e-4, 0.4864e-4, 0.4864e-4
    Icxx, Icyy, Iczz = 0.959e-4, 0.959e-4, 0.0051e-4
    Ibexx, Ibeyy, Ibezz = 11.09e-4, 10.06e-4, 0.591e-4
    Idfxx, Idfyy, Idfzz, Ibaseyy = 7.11e-4, 0.629e-4, 6.246e-4, 11.87e-4
    M = np.zeros((3, 3))
    M[0, 0] = (0.125 * (4 * Iayy + 4 * Iazz + 8 * Ibaseyy + 4 * Ibeyy + 4 * Ibezz + 4 * Icyy
                        + 4 * Iczz + 4 * Idfyy + 4 * Idfzz + 4 * L1**2 * ma + L2**2 * ma
                        + L1**2 * mc + 4 * L3**2 * mc)
               + 0.125 * (4 * Ibeyy - 4 * Ibezz + 4 * Icyy - 4 * Iczz + L1**2 * (4 * ma + mc))
               * np.cos(2 * q2)
               + 0.125 * (4 * Iayy - 4 * Iazz + 4 * Idfyy - 4 * Idfzz - L2**2 * ma
                          - 4 * L3**2 * mc) * np.cos(2 * q3)
               + L1 * (L2 * ma + L3 * mc) * np.cos(q2) * np.sin(q3))
    M[1, 1] = 0.25 * (4 * (Ibexx + Icxx + L1**2 * ma) + L1**2 * mc)
    M[1, 2] = M[2, 1] = -0.5 * L1 * (L2 * ma + L3 * mc) * np.sin(q2 - q3)
    M[2, 2] = 0.25 * (4 * Iaxx + 4 * Idfxx + L2**2 * ma + 4 * L3**2 * mc)
    return M


def postures(robot, n, seed):
    rng = np.random.default_rng(seed)
    lower, upper = robot.position_limits
    out = []
    while len(out) < n:
        q = rng.uniform(lower, upper)
        q[0] = rng.uniform(-1.5, 1.5)
        if all(lo <= c @ q <= hi for c, lo, hi in robot.coupling):
            out.append(q)
    return out


@pytest.fixture(scope="module")
def solidworks():
    return load_robot("phantom")


@pytest.fixture(scope="module")
def cavusoglu():
    return load_robot("phantom-cavusoglu")


def test_forward_kinematics_is_the_sources(solidworks):
    """PhantomModel.cpp forward_kinematics: r = l1 cos q2 + l2 sin q3, z = l1 sin q2 − l2 cos q3."""
    l1, l2 = 0.209550, 0.169545
    for q in postures(solidworks, 100, 0):
        q2, q3 = to_source(q)
        r = l1 * np.cos(q2) + l2 * np.sin(q3)
        ref = [np.cos(q[0]) * r, np.sin(q[0]) * r, l1 * np.sin(q2) - l2 * np.cos(q3)]
        np.testing.assert_allclose(solidworks.ee_position(q), ref, atol=1e-15)


@pytest.mark.parametrize("name, source", [("phantom", gravity_solidworks),
                                          ("phantom-cavusoglu", gravity_cavusoglu)])
def test_gravity_is_the_sources(name, source):
    """Generalized gravity of the URDF (Pinocchio) = Tᵀ G_src(q_src), both parameter sets; at
    home the arm is lifted (back-heavy) and the elbow's gravity stiffness is negative."""
    robot = load_robot(name)
    data = robot.create_data()
    for q in postures(robot, 100, 1):
        g = pin.computeGeneralizedGravity(robot.model, data, q)
        np.testing.assert_allclose(g[1:], T.T @ source(*to_source(q)), atol=1e-15)
        assert abs(g[0]) < 1e-15
    home = pin.computeGeneralizedGravity(robot.model, data, robot.q0)
    assert 0.010 < home[1] < 0.017  # N·m: gravity exerts −g, lifting the arm
    h = 1e-6
    stiffness = (pin.computeGeneralizedGravity(robot.model, data, robot.q0 + np.array([0, 0, h]))[2]
                 - home[2]) / h
    assert -0.09 < stiffness < -0.07  # N·m/rad (Çavuşoğlu −0.0737, SolidWorks −0.0873)


def test_cavusoglu_mass_matrix_is_the_closed_form(cavusoglu):
    """The tree with mimic joints reproduces the published closed-form M(q) (no rotors)."""
    model = pin.buildModelFromUrdf(urdf_path("phantom_premium_1_5a_cavusoglu.urdf"), mimic=True)
    data = model.createData()
    for q in postures(cavusoglu, 100, 2):
        M = pin.crba(model, data, q)
        M = np.triu(M) + np.triu(M, 1).T
        ref = T_FULL.T @ mass_cavusoglu(*to_source(q)) @ T_FULL
        np.testing.assert_allclose(M, ref, atol=1e-10)


def test_rotor_inertia_acts_on_the_motor_angles(solidworks):
    """M(q) − M_links(q) = Sᵀ diag(η² J_m) S: the elbow rotor on the forearm's absolute angle."""
    bare = pin.buildModelFromUrdf(urdf_path("phantom_premium_1_5a.urdf"), mimic=True)
    bare.gravity.linear[:] = [0.0, 0.0, -G]
    S = solidworks.motor_map
    rotor = np.array([13.3, 11.2, 11.2]) ** 2 * 1.03e-6  # η² J_m (phantom.toml's drives)
    np.testing.assert_allclose(solidworks.rotor_inertia, rotor)
    for q in postures(solidworks, 20, 3):
        Mb = pin.crba(bare, bare.createData(), q)
        Mb = np.triu(Mb) + np.triu(Mb, 1).T
        np.testing.assert_allclose(solidworks.mass_matrix(q) - Mb, S.T @ np.diag(rotor) @ S,
                                   atol=1e-15)


def test_mimic_dynamics_equal_the_projected_tree(solidworks):
    """forward_dynamics on the mimic model = the five-joint tree's M₅, h₅ projected with the
    constant map q₅ = (q1, q2, q3, q3, −q3): M = PᵀM₅P, h = Pᵀh₅."""
    tree = pin.buildModelFromUrdf(urdf_path("phantom_premium_1_5a.urdf"))
    tree.gravity.linear[:] = [0.0, 0.0, -G]
    tree.armature[:] = [*solidworks.model.armature, 0.0, 0.0]
    tree.inertias[4] = solidworks.model.inertias[4]  # the elbow rotor on the crank body
    P = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 0, 1], [0, 0, -1]], dtype=float)
    rng = np.random.default_rng(4)
    data, tdata = solidworks.create_data(), tree.createData()
    for q in postures(solidworks, 30, 5):
        v, tau = rng.normal(size=3), rng.normal(size=3) * 0.3
        M5 = pin.crba(tree, tdata, P @ q)
        M5 = np.triu(M5) + np.triu(M5, 1).T
        h5 = pin.rnea(tree, tdata, P @ q, P @ v, np.zeros(5))
        ref = np.linalg.solve(P.T @ M5 @ P, tau - P.T @ h5)
        got = forward_dynamics(solidworks.model, data, q, v, tau)
        np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())


def test_limits_are_the_sources():
    """validate_angles (PhantomModel.cpp) and the limits of PhantomModel.hpp, in the source's
    angles, accept exactly the postures the model accepts."""
    robot = load_robot("phantom")
    rng = np.random.default_rng(6)
    lo = np.radians([-90.0, -124.0, -29.0])
    hi = np.radians([90.0, 119.0, 214.0])
    agree = 0
    for _ in range(3000):
        q1, q2s, q3s = rng.uniform(lo - 0.3, hi + 0.3)
        valid = (lo[0] <= q1 <= hi[0] and lo[1] <= q2s <= hi[1] and lo[2] <= q3s <= hi[2]
                 and q2s - q3s <= np.radians(65) and q3s - q2s <= np.radians(55))
        q = np.array([q1, -q2s, np.pi / 2 - q3s + q2s])
        try:
            robot.check_posture(q)
            accepted = True
        except ValueError:
            accepted = False
        assert accepted == valid
        agree += valid
    assert agree > 300  # both outcomes were exercised
