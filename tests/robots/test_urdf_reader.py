"""A URDF's size and physics checked before Pinocchio's native parser reads it, and that
parser's own messages turned into one line."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from rhmpc.robots.registry import urdf_path
from rhmpc.robots.urdf_reader import (
    MAX_CHAIN,
    MAX_LINKS,
    UrdfError,
    check_urdf,
    read_model,
)

PHANTOM = Path(urdf_path("phantom_premium_1_5a.urdf")).read_text()


def first(pattern: str, new: str) -> str:
    """The PHANToM's URDF with the first match of ``pattern`` replaced."""
    text = re.sub(pattern, new, PHANTOM, count=1)
    assert text != PHANTOM
    return text


def chain(n: int, parent: str = "tip", kind: str = "revolute") -> str:
    """The PHANToM's URDF with a chain of ``n`` light links appended below ``parent``."""
    links = []
    for i in range(n):
        up = parent if i == 0 else f"x{i - 1}"
        links.append(
            f'<link name="x{i}"><inertial><mass value="0.01"/><inertia ixx="1e-6" ixy="0" '
            f'ixz="0" iyy="1e-6" iyz="0" izz="1e-6"/></inertial></link><joint name="xj{i}" '
            f'type="{kind}"><parent link="{up}"/><child link="x{i}"/><axis xyz="0 0 1"/>'
            '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>')
    return PHANTOM.replace("</robot>", "".join(links) + "</robot>")


#: (what changes in the PHANToM's URDF, what the one line names)
BAD = {
    "mass nan": (first(r'<mass value="[^"]*"', '<mass value="nan"'), "mass"),
    "mass negative": (first(r'<mass value="[^"]*"', '<mass value="-0.36"'), "mass"),
    "mass zero, inertia not": (first(r'<mass value="[^"]*"', '<mass value="0"'), "mass"),
    "mass infinite": (first(r'<mass value="[^"]*"', '<mass value="inf"'), "mass"),
    "mass a boolean": (first(r'<mass value="[^"]*"', '<mass value="true"'), "mass"),
    "mass missing": (first(r'<mass value="[^"]*"/>', ""), "mass"),
    "inertia negative": (first(r'ixx="[^"]*"', 'ixx="-1.5e-03"'), "inertia"),
    "inertia text": (first(r'ixx="[^"]*"', 'ixx="heavy"'), "ixx"),
    "inertia indefinite": (first(r'ixy="[^"]*"', 'ixy="1"'), "semi-definite"),
    "inertia beyond the triangle": (first(r'izz="[^"]*"', 'izz="1"'), "triangle"),
    "origin nan": (first(r'xyz="[^"]*"', 'xyz="nan 0 0"'), "origin"),
    "origin two numbers": (first(r'xyz="[^"]*"', 'xyz="0 0"'), "origin"),
    "origin 1e300 m away": (first(r'xyz="[^"]*"', 'xyz="1e300 0 0"'), "origin xyz"),
    "axis zero": (first(r'<axis xyz="[^"]*"', '<axis xyz="0 0 0"'), "axis"),
    "effort negative": (first(r'effort="[^"]*"', 'effort="-1"'), "effort"),
    "velocity text": (first(r'velocity="[^"]*"', 'velocity="fast"'), "velocity"),
    "too deep": (chain(MAX_CHAIN + 1), "joints from the root"),
    "too many links": (chain(MAX_LINKS + 1, kind="fixed"), "links"),
    "a loop": (PHANTOM.replace("</robot>", '<joint name="c" type="fixed"><parent link="tip"/>'
                               '<child link="base_link"/></joint></robot>'), "loop"),
    "two parents": (PHANTOM.replace("</robot>", '<joint name="c" type="fixed"><parent '
                                    'link="base_link"/><child link="tip"/></joint></robot>'),
                    "two joints"),
    "entities": ('<?xml version="1.0"?><!DOCTYPE r [<!ENTITY a "aaaa">]><robot name="r"/>',
                 "entities"),
    "nested XML": (PHANTOM.replace("</robot>", "<a>" * 100 + "</a>" * 100 + "</robot>"),
                   "nested"),
    "not XML": (PHANTOM[:len(PHANTOM) // 2], "not XML"),
    "not a robot": ("<robots/>", "<robots>"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_a_bad_urdf_is_one_line_naming_the_problem(case: str) -> None:
    text, named = BAD[case]
    with pytest.raises(UrdfError) as info:
        check_urdf(text)
    assert "\n" not in str(info.value) and named in str(info.value), str(info.value)


def test_a_chain_as_deep_as_allowed_is_read() -> None:
    """The deepest chain allowed, through the native parser (its recursion) into a model."""
    model = read_model(chain(MAX_CHAIN - 6))  # the PHANToM's tip is 6 joints deep
    assert model.njoints == 6 + MAX_CHAIN - 6


def box(mass: float, sides: np.ndarray) -> np.ndarray:
    """A solid box's principal moments about its centre, m (b² + c²) / 12, … [kg·m²]."""
    a, b, c = sides**2
    return mass / 12.0 * np.array([b + c, a + c, a + b])


def with_inertia(moments, rotation: np.ndarray, mass: float = 0.2) -> str:
    inertia = rotation @ np.diag(moments) @ rotation.T
    values = {k: inertia[i, j] for k, (i, j) in zip(
        ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"),
        ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)), strict=True)}
    attributes = " ".join(f'{k}="{v:.17g}"' for k, v in values.items())
    text = first(r'<mass value="[^"]*"/>\s*<inertia[^>]*/>',
                 f'<mass value="{mass!r}"/><inertia {attributes}/>')
    return text


def test_bodies_pass_and_impossible_tensors_fail() -> None:
    """Boxes of random sides, rotated at random, pass (the triangle inequality holds for any
    body, with equality for a flat one); a moment raised past the sum of the two others, or a
    negative one, fails."""
    rng = np.random.default_rng(7)
    for _ in range(20):
        rotation = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        sides = rng.uniform(0.0, 0.3, size=3)
        sides[rng.integers(3)] *= rng.integers(2)  # flat boxes too: equality
        moments = box(0.2, sides)
        check_urdf(with_inertia(moments, rotation))
        raised = moments.copy()
        raised[2] = (moments[0] + moments[1]) * 1.01 + 1e-9
        with pytest.raises(UrdfError, match="triangle"):
            check_urdf(with_inertia(raised, rotation))
        with pytest.raises(UrdfError, match="semi-definite"):
            check_urdf(with_inertia(moments - 1.01 * moments.max(), rotation))


def test_a_published_set_may_keep_its_inertia() -> None:
    """The links named as published are spared the triangle inequality, not the rest."""
    text = first(r'izz="[^"]*"', 'izz="1"')
    check_urdf(text, frozenset({"turret"}))
    with pytest.raises(UrdfError, match="semi-definite"):
        check_urdf(first(r'ixx="[^"]*"', 'ixx="-1"'), frozenset({"turret"}))


def test_a_frame_without_a_body_passes() -> None:
    """Mass 0 with a zero inertia: a frame, as the UR5's and the Panda's URDFs write them."""
    check_urdf(first(r'<mass value="[^"]*"/>\s*<inertia[^>]*/>',
                     '<mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" '
                     'izz="0"/>'))


def test_urdfdoms_messages_become_the_one_line(capfd) -> None:
    """What urdfdom writes on the process's standard error is kept from the terminal; its
    first error is the message."""
    text = PHANTOM.replace("<inertial>", '<collision><origin xyz="nan 0 0"/><geometry><box '
                           'size="1 1 1"/></geometry></collision><inertial>', 1)
    with pytest.raises(UrdfError, match=r"Unable to parse component \[nan\]"):
        read_model(text)
    parent = first(r'<parent link="[^"]*"/>', '<parent link="nowhere"/>')
    with pytest.raises(UrdfError, match=r"parent link \[nowhere\]"):
        read_model(parent)
    assert capfd.readouterr().err == ""
