"""Robot files: a URDF, three joints, the tool and the home; checked before anything runs."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from rhmpc.io import FileError
from rhmpc.robots import ROBOTS, load_robot
from rhmpc.robots.description import RobotFileError, robot_from_file
from rhmpc.robots.registry import urdf_path

PANDA = """urdf = "panda.urdf"
joints = ["panda_joint1", "panda_joint2", "panda_joint4"]
locked = { panda_joint3 = 0.0, panda_joint5 = 0.0, panda_joint6 = 1.5708, panda_joint7 = 0.7854 }
tool_frame = "panda_hand_tcp"
home = [0.0, 0.3, -1.8]
"""


def shipped(relative: str) -> Path:
    """A URDF of example-robot-data's robots."""
    from example_robot_data.robots_loader import getModelPath

    return Path(getModelPath(relative)) / relative


def panda_urdf() -> Path:
    return shipped("panda_description/urdf/panda.urdf")


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    """A folder with the Panda's URDF and no meshes beside it."""
    shutil.copy(panda_urdf(), tmp_path / "panda.urdf")
    return tmp_path


def write(folder: Path, text: str, name: str = "robot.toml") -> Path:
    path = folder / name
    path.write_text(text)
    return path


def test_registered_robots_are_robot_files():
    for name in ROBOTS:
        robot = load_robot(name)
        assert robot.name == name
        assert robot_from_file(urdf_path(f"{name}.toml")).model.nq == robot.model.nq == 3


def test_panda_from_its_urdf_alone(folder):
    """Without its meshes; the fingers (named nowhere) at their neutral value; torque limits and
    damping from the URDF; the locked joints where the file says."""
    robot = robot_from_file(write(folder, PANDA, "panda.toml"))
    assert robot.name == "panda" and robot.nv == 3
    assert [robot.model.names[j] for j in (1, 2, 3)] == ["panda_joint1", "panda_joint2",
                                                          "panda_joint4"]
    np.testing.assert_array_equal(robot.torque_limit, [87.0, 87.0, 87.0])
    np.testing.assert_array_equal(robot.damping, [0.003, 0.003, 0.003])
    full = pin.buildModelFromUrdf(str(panda_urdf()))
    q = pin.neutral(full)
    q[[0, 1, 2, 3, 4, 5, 6]] = [0.0, 0.3, 0.0, -1.8, 0.0, 1.5708, 0.7854]
    data = full.createData()
    pin.framesForwardKinematics(full, data, q)
    np.testing.assert_allclose(robot.ee_position(robot.q0),
                               data.oMf[full.getFrameId("panda_hand_tcp")].translation,
                               atol=1e-12)


def test_a_point_on_a_frame_is_the_tool(folder):
    """The hand's TCP lies 0.1034 m along link 8's z axis (panda.urdf's hand joint turns about
    z, its TCP joint moves along z): the same point as a frame or as a point on link 8."""
    point = PANDA.replace('tool_frame = "panda_hand_tcp"',
                          'tool = { frame = "panda_link8", point = [0.0, 0.0, 0.1034] }')
    a = robot_from_file(write(folder, PANDA, "a.toml"))
    b = robot_from_file(write(folder, point, "b.toml"))
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = a.q0 + rng.normal(scale=0.1, size=3)
        np.testing.assert_allclose(b.ee_position(q), a.ee_position(q), atol=1e-12)
        np.testing.assert_allclose(b.ee_jacobian(q), a.ee_jacobian(q), atol=1e-12)


def test_a_users_file_of_a_registered_arm_is_that_arm(folder):
    """The UR5's file, copied with its URDF beside it: the same dynamics as the registry's."""
    shutil.copy(shipped("ur_description/urdf/ur5_robot.urdf"), folder / "ur5.urdf")
    text = Path(urdf_path("ur5.toml")).read_text().replace(
        "package://ur_description/urdf/ur5_robot.urdf", "ur5.urdf")
    mine, registered = robot_from_file(write(folder, text)), load_robot("ur5")
    q = registered.q0 + 0.1
    np.testing.assert_allclose(mine.mass_matrix(q), registered.mass_matrix(q), rtol=1e-14)
    np.testing.assert_allclose(mine.ee_position(q), registered.ee_position(q), rtol=1e-14)


#: (what changes in the Panda's file, the key the one-line error names)
BAD = {
    "missing joint": (('"panda_joint2"', '"panda_joint22"'), "joints"),
    "torque limit 0": (("home =", "torque_limits = [87.0, 0.0, 87.0]\nhome ="), "torque_limits"),
    "home outside limits": (("[0.0, 0.3, -1.8]", "[0.0, 3.0, -0.01]"), "home"),
    "home not three": (("[0.0, 0.3, -1.8]", "[0.0, 0.3]"), "home"),
    "singular home": (("[0.0, 0.3, -1.8]", "[0.0, 0.0, -0.0698]"), "home"),
    "workspace out of reach": (("home =", "workspace = 0.5\nhome ="), "workspace"),
    "unknown key": (("home =", "homes = 1\nhome ="), "homes"),
    "locked unknown": (("panda_joint3 = 0.0", "panda_joint9 = 0.0"), "locked"),
    "locked actuated": (("panda_joint3 = 0.0", "panda_joint2 = 0.0"), "locked"),
    "locked out of limits": (("panda_joint6 = 1.5708", "panda_joint6 = 5.0"), "locked"),
    "no tool frame": (('"panda_hand_tcp"', '"hand"'), "tool_frame"),
    "missing urdf": (('"panda.urdf"', '"nowhere.urdf"'), "urdf"),
    "joints out of order": (('"panda_joint1", "panda_joint2"', '"panda_joint2", "panda_joint1"'),
                            "joints"),
    "a prismatic joint": (('"panda_joint4"', '"panda_finger_joint1"'), "joints"),
    "not TOML": (("home =", "home = = "), "TOML"),
    "negative damping": (("home =", "damping = [0.0, -1.0, 0.0]\nhome ="), "damping"),
    "drives incomplete": (("home = [0.0, 0.3, -1.8]\n",
                           "home = [0.0, 0.3, -1.8]\n[drives]\ngear_ratio = [1.0, 1.0, 1.0]\n"),
                          "drives.peak_torque"),
    "home booleans": (("[0.0, 0.3, -1.8]", "[true, false, true]"), "home"),
    "home text": (("[0.0, 0.3, -1.8]", '["0", "0.3", "-1.8"]'), "home"),
    "gravity 1e300": (("home =", "gravity = 1e300\nhome ="), "gravity"),
    "gravity in cm/s²": (("home =", "gravity = 981\nhome ="), "gravity"),
    "tool point 1e6 m": (('tool_frame = "panda_hand_tcp"',
                          'tool = { frame = "panda_link8", point = [1e6, 0.0, 0.0] }'),
                         "tool.point"),
    "torque limits 1e300": (("home =", "torque_limits = [1e300, 1e300, 1e300]\nhome ="),
                            "torque_limits"),
    "armature 1e300": (("home =", "armature = [1e300, 0.0, 0.0]\nhome ="), "armature"),
    "friction beyond the limits": (("home =", "friction = [90.0, 0.0, 0.0]\nhome ="),
                                   "friction"),
    "torque limits too weak to hold home": (("home =", "torque_limits = [1.0, 1.0, 1.0]\n"
                                             "home ="), "home"),
    "a fractional encoder count": (("home = [0.0, 0.3, -1.8]\n",
                                    "home = [0.0, 0.3, -1.8]\n[drives]\n"
                                    "gear_ratio = [1.0, 1.0, 1.0]\npeak_torque = 100.0\n"
                                    "torque_constant = 0.1\nno_load_current = 0.1\n"
                                    "rotor_inertia = 1e-6\nencoder_counts = 4096.5\n"),
                                   "drives.encoder_counts"),
    "inconsistent_inertia of no link": (("home =", 'inconsistent_inertia = ["nope"]\nhome ='),
                                        "inconsistent_inertia"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_a_bad_file_says_which_key(folder, case):
    (old, new), key = BAD[case]
    text = PANDA.replace(old, new)
    assert text != PANDA
    path = write(folder, text)
    with pytest.raises((RobotFileError, FileError)) as info:  # FileError: the reader's own
        robot_from_file(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(f"{path}: ")
    assert key in message


def test_a_urdf_without_effort_limits_needs_torque_limits(folder):
    urdf = (folder / "panda.urdf").read_text().replace('effort="87.0"', 'effort="0"')
    (folder / "panda.urdf").write_text(urdf)
    with pytest.raises(RobotFileError, match="torque_limits: the URDF gives no effort limit"):
        robot_from_file(write(folder, PANDA))
    robot = robot_from_file(write(folder, PANDA + "torque_limits = [80.0, 80.0, 80.0]\n"))
    np.testing.assert_array_equal(robot.torque_limit, [80.0, 80.0, 80.0])


def test_drives_give_the_phantoms_numbers():
    """The PHANToM's [drives] (gear ratios, motor data) against the figures they derive."""
    robot = load_robot("phantom")
    eta = np.array([13.3, 11.2, 11.2])
    np.testing.assert_allclose(robot.gear_ratio, eta)
    np.testing.assert_allclose(robot.torque_limit, 0.129 * eta)
    np.testing.assert_allclose(robot.coulomb_friction, 0.0234 * 0.0263 * eta)


def test_unknown_names_and_files():
    with pytest.raises(ValueError, match=r"or a robot file FILE\.toml"):
        load_robot("puma")
    with pytest.raises(FileError, match=r"nosuch.toml: no such file"):
        load_robot("nosuch.toml")


#: (what changes in the Panda's URDF, what the one line names)
BAD_URDF = {
    "a mass nan": (('<mass value="0.646926"', '<mass value="nan"'), "mass"),
    "a negative inertia": (('ixx="0.007962"', 'ixx="-0.007962"'), "inertia"),
    "a link of 1e300 kg": (('<mass value="0.646926"', '<mass value="1e300"'), "mass matrix"),
}


@pytest.mark.parametrize("case", list(BAD_URDF))
def test_the_urdfs_physics_is_checked_before_a_run(folder, case):
    (old, new), named = BAD_URDF[case]
    urdf = (folder / "panda.urdf").read_text()
    assert old in urdf
    (folder / "panda.urdf").write_text(urdf.replace(old, new, 1))
    with pytest.raises(RobotFileError) as info:
        robot_from_file(write(folder, PANDA))
    assert "\n" not in str(info.value) and "urdf: " in str(info.value)
    assert named in str(info.value)


def test_a_urdf_given_as_the_robot_says_a_robot_file_is_expected(folder):
    with pytest.raises(RobotFileError, match=r"a robot file \(TOML\) is expected"):
        robot_from_file(folder / "panda.urdf")
    with pytest.raises(FileError, match="a robot file is TOML"):
        robot_from_file(write(folder, "<robot/>\n"))


def test_a_missing_tool_frame_lists_the_frames(folder):
    with pytest.raises(RobotFileError, match=r"its frames: .*panda_hand_tcp"):
        robot_from_file(write(folder, PANDA.replace('"panda_hand_tcp"', '"hand"')))


def test_no_tool_at_all_lists_the_frames(folder):
    """Neither tool_frame nor tool: one line naming the key and the URDF's frames."""
    missing = PANDA.replace('tool_frame = "panda_hand_tcp"\n', "")
    assert missing != PANDA
    said = r"toml: tool_frame: missing; .*frames: .*panda_hand_tcp"
    with pytest.raises(RobotFileError, match=said):
        robot_from_file(write(folder, missing))
    both = PANDA + 'tool = { frame = "panda_link8", point = [0.0, 0.0, 0.1] }\n'
    with pytest.raises(RobotFileError, match="not both"):
        robot_from_file(write(folder, both))


def test_every_registered_robot_holds_its_home_within_its_limits():
    """The registered arms pass the checks a user's file meets: M(q₀) positive definite and
    the gravity torque at home within the torque limits."""
    for name in ROBOTS:
        robot = load_robot(name)
        assert np.linalg.eigvalsh(robot.mass_matrix(robot.q0))[0] > 0
        gravity = pin.computeGeneralizedGravity(robot.model, robot.create_data(), robot.q0)
        assert np.all(np.abs(gravity) < robot.torque_limit), name
