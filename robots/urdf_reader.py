"""A URDF checked before a native parser reads it, then read by Pinocchio with its messages kept.

Pinocchio reads a URDF through urdfdom, a C++ parser that walks the kinematic tree
recursively, prints its complaints on the process's standard error, and drops an element it
cannot read (a mass ``nan``, an inertia ``heavy``) and goes on: the link becomes massless,
silently. So the text is parsed here first (:func:`check_urdf`: Python's expat, bounded), and
its numbers and its bodies' physics are checked:

- at most :data:`MAX_LINKS` links, at most :data:`MAX_CHAIN` of them on the way from the root
  to any link, and XML at most :data:`MAX_XML_DEPTH` elements deep, checked while it is parsed;
- every number of the kinematics and the dynamics is a finite decimal number (``nan``,
  ``inf``, ``true`` and text are refused): origins (within :data:`MAX_OFFSET` of their
  parent), axes (not zero), joint limits (efforts and speeds ≥ 0), joint dynamics (≥ 0),
  masses and inertias;
- each body's mass m is finite and > 0, and its rotational inertia about its centre of mass
  I_c (the symmetric matrix of ``ixx`` … ``izz``) is positive semi-definite with principal
  moments that satisfy the triangle inequality I₁ + I₂ ≥ I₃ for each ordering: those of a
  distribution of mass (Traversaro, Brossette, Escande and Nori, "Identification of fully
  physical consistent inertial parameters using optimization on manifolds", IROS 2016, §III).
  A thin rod (one moment 0) passes; a link of mass 0 whose inertia is 0 is a frame without a
  body (a tool centre point), as URDFs write them. The links of ``unchecked`` (a published
  parameter set that breaks the triangle inequality, kept as published) are spared that
  inequality only.

Then :func:`read_model` builds the model with the process's standard error captured: a line
urdfdom writes as ``Error:`` becomes the one line of the :class:`UrdfError`, even where
Pinocchio returned a model (it would lack what urdfdom dropped).
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Iterator

import numpy as np
import pinocchio as pin

__all__ = ["MAX_CHAIN", "MAX_LINKS", "MAX_XML_DEPTH", "UrdfError", "check_urdf", "read_model"]

#: The most links a URDF may hold. The largest arm of example-robot-data holds 13 and its
#: largest robot (a two-armed mobile manipulator) 130; the 3-joint model keeps three of them.
MAX_LINKS = 1000
#: The most links on the way from the root to any link. urdfdom walks the tree recursively:
#: a chain of 5 000 links overflowed its stack of 8 MiB (a segmentation fault), one of 3 000 did
#: not; a thread's stack may be smaller, so the bound stays well below.
MAX_CHAIN = 256
#: The deepest nesting of XML elements read (a URDF nests 4: robot, link, inertial, mass).
MAX_XML_DEPTH = 64
#: The most XML elements read (visuals, collisions and simulator tags included).
MAX_ELEMENTS = 200_000
#: The farthest a joint or a centre of mass lies from its parent frame [m]: no arm is larger;
#: beyond it is a unit error (millimetres written as metres) or a typo.
MAX_OFFSET = 100.0
#: How much of urdfdom's captured messages is read [B].
MAX_CAPTURED = 1 << 16
#: Tolerance of the inertia checks: relative, of the largest principal moment (the rounding
#: of a URDF's printed values: the registered PHANToM's hold 5 significant digits), and
#: absolute [kg·m²] (a zero tensor's rounding: a gram at a micrometre is 10⁻¹⁵ kg·m²).
INERTIA_RTOL = 1e-6
INERTIA_ATOL = 1e-12
_DECIMAL = re.compile(r"\s*[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*")
_INERTIA = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")
_MOVING = ("revolute", "continuous", "prismatic")


class UrdfError(ValueError):
    """A URDF that does not describe a model of rigid bodies; one line, naming the element."""


def _number(text: str | None, where: str) -> float:
    """``text`` as a finite decimal number (not ``nan``, ``inf``, a word or empty)."""
    if text is None or not _DECIMAL.fullmatch(text) or not math.isfinite(float(text)):
        raise UrdfError(f"{where} must be a finite number, got {text!r}")
    return float(text)


def _vector(element: ET.Element | None, attribute: str, where: str) -> np.ndarray:
    """Three numbers of ``element``'s ``attribute`` (absent: zeros, as urdfdom reads it)."""
    text = None if element is None else element.get(attribute)
    if text is None:
        return np.zeros(3)
    parts = text.split()
    if len(parts) != 3:
        raise UrdfError(f"{where} {attribute} must be 3 numbers, got {text!r}")
    return np.array([_number(p, f"{where} {attribute}") for p in parts])


def _origin(element: ET.Element | None, where: str) -> None:
    """An ``<origin>``: three finite angles, and an offset within :data:`MAX_OFFSET` along
    each axis."""
    _vector(element, "rpy", where)
    offset = float(np.abs(_vector(element, "xyz", where)).max())
    if offset > MAX_OFFSET:
        raise UrdfError(f"{where} xyz is {offset:.4g} m from its parent along an axis; at "
                        f"most {MAX_OFFSET:g} m (metres, not millimetres)")


def _parse(text: str) -> ET.Element:
    """The XML's root, parsed incrementally with its depth, elements and links bounded."""
    if "<!ENTITY" in text:
        raise UrdfError("declares XML entities, which a URDF has no use for")
    parser = ET.XMLPullParser(events=("start", "end"))
    depth = elements = links = 0
    root = None
    try:
        for start in range(0, len(text), 1 << 16):
            parser.feed(text[start:start + (1 << 16)])
            for event, element in parser.read_events():
                if event == "end":
                    depth -= 1
                    continue
                depth, elements = depth + 1, elements + 1
                root = element if root is None else root
                links += element.tag == "link" and depth == 2
                if depth > MAX_XML_DEPTH:
                    raise UrdfError(f"XML nested deeper than {MAX_XML_DEPTH} elements")
                if links > MAX_LINKS:
                    raise UrdfError(f"more than {MAX_LINKS} links: too large a robot to read")
                if elements > MAX_ELEMENTS:
                    raise UrdfError(f"more than {MAX_ELEMENTS} XML elements: too large a "
                                    "robot to read")
        parser.close()
    except ET.ParseError as exc:
        raise UrdfError(f"not XML ({exc})") from None
    if root is None:
        raise UrdfError("no XML element")
    return root


def _chain_depth(root: ET.Element) -> None:
    """Every link at most :data:`MAX_CHAIN` joints from the root, each with one parent, and no
    loop (an iterative walk: the check must not recurse where urdfdom would)."""
    parent: dict[str, str] = {}
    for joint in root.iter("joint"):
        p, c = joint.find("parent"), joint.find("child")
        if p is None or c is None or joint.get("name") is None:
            continue  # urdfdom names what is missing
        child = c.get("link")
        if child in parent:
            raise UrdfError(f"link {child!r} is the child of two joints")
        parent[child] = p.get("link")
    depth: dict[str, int] = {}
    for link in parent:
        path, node = [], link
        while node in parent and node not in depth:
            path.append(node)
            if len(path) > len(parent):
                raise UrdfError(f"the joints form a loop through link {link!r}")
            node = parent[node]
        for i, name in enumerate(reversed(path), start=depth.get(node, 0) + 1):
            depth[name] = i
        if path and depth[link] > MAX_CHAIN:
            raise UrdfError(f"link {link!r} is {depth[link]} joints from the root; at most "
                            f"{MAX_CHAIN} are read")


def _inertial(link: ET.Element, unchecked: frozenset[str]) -> None:
    """The body of ``link``: m > 0 and I_c ⪰ 0 with the triangle inequality (module
    docstring), or m = 0 and I_c = 0 (a frame)."""
    inertial = link.find("inertial")
    if inertial is None:
        return
    name = link.get("name")
    where = f"link {name!r}"
    _origin(inertial.find("origin"), f"{where} inertial origin")
    mass, tensor = inertial.find("mass"), inertial.find("inertia")
    if mass is None or tensor is None:
        raise UrdfError(f"{where}: an <inertial> needs a <mass> and an <inertia>")
    m = _number(mass.get("value"), f"{where} mass")
    i = {k: _number(tensor.get(k), f"{where} inertia {k}") for k in _INERTIA}
    inertia = np.array([[i["ixx"], i["ixy"], i["ixz"]], [i["ixy"], i["iyy"], i["iyz"]],
                        [i["ixz"], i["iyz"], i["izz"]]])
    if m < 0 or (m == 0 and np.any(inertia)):
        raise UrdfError(f"{where} mass must be > 0 (or 0 with a zero inertia: a frame), got "
                        f"{m:g} kg")
    moments = np.linalg.eigvalsh(inertia)
    tol = INERTIA_RTOL * abs(moments).max() + INERTIA_ATOL
    if moments[0] < -tol:
        raise UrdfError(f"{where} inertia is not positive semi-definite: principal moments "
                        f"{_moments(moments)} kg·m²")
    if name not in unchecked and moments[0] + moments[1] < moments[2] - tol:
        raise UrdfError(f"{where} inertia breaks the triangle inequality: principal moments "
                        f"{_moments(moments)} kg·m², {moments[0]:.4g} + {moments[1]:.4g} < "
                        f"{moments[2]:.4g}; no body has them")


def _moments(moments: np.ndarray) -> str:
    return ", ".join(f"{v:.4g}" for v in moments)


def _joint(joint: ET.Element) -> None:
    """The numbers of ``joint``: its origin, its axis (not zero), limits and dynamics."""
    where = f"joint {joint.get('name')!r}"
    _origin(joint.find("origin"), f"{where} origin")
    if joint.get("type") in _MOVING and joint.find("axis") is not None:
        if not np.any(_vector(joint.find("axis"), "xyz", f"{where} axis")):
            raise UrdfError(f"{where} axis must not be zero")
    for tag, keys in (("limit", ("lower", "upper", "effort", "velocity")),
                      ("dynamics", ("damping", "friction")), ("mimic", ("multiplier", "offset"))):
        element = joint.find(tag)
        for key in keys if element is not None else ():
            if element.get(key) is None:
                continue
            value = _number(element.get(key), f"{where} {tag} {key}")
            if value < 0 and key in ("effort", "velocity", "damping", "friction"):
                raise UrdfError(f"{where} {tag} {key} must be ≥ 0, got {value:g}")


def check_urdf(text: str, unchecked: frozenset[str] = frozenset()) -> None:
    """Raise :class:`UrdfError` for the first problem of the URDF ``text`` (module docstring);
    ``unchecked``: links spared the triangle inequality."""
    root = _parse(text)
    if root.tag != "robot":
        raise UrdfError(f"the root element is <{root.tag}>, not <robot>")
    _chain_depth(root)
    for link in root.findall("link"):
        _inertial(link, unchecked)
    for joint in root.findall("joint"):
        _joint(joint)


@contextlib.contextmanager
def _stderr_kept() -> Iterator[list[str]]:
    """Inside, what the process writes on its standard error (file descriptor 2, native code
    included) is kept, not shown; its lines are in the list once the block ends."""
    lines: list[str] = []
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with tempfile.TemporaryFile() as sink:
            os.dup2(sink.fileno(), 2)
            try:
                yield lines
            finally:
                os.dup2(saved, 2)
                sink.seek(0)
                lines += sink.read(MAX_CAPTURED).decode("utf-8", "replace").splitlines()
    finally:
        os.close(saved)


def _urdfdom_error(lines: list[str]) -> str | None:
    """urdfdom's first ``Error:`` message, without the source line it adds."""
    for line in lines:
        if line.strip().startswith("Error:"):
            return " ".join(line.strip()[len("Error:"):].split())
    return None


def read_model(text: str, unchecked: frozenset[str] = frozenset()) -> pin.Model:
    """The URDF's model (mimic joints follow their joints, no meshes), once :func:`check_urdf`
    passed; urdfdom's messages are kept from the terminal and its first error is raised.

    Raises
    ------
    UrdfError
        The first problem, on one line.
    """
    check_urdf(text, unchecked)
    with _stderr_kept() as lines:
        try:
            model = pin.buildModelFromXML(text, mimic=True)
        except (RuntimeError, ValueError) as exc:
            model, failure = None, (str(exc).strip().splitlines() or ["unknown error"])[0]
    error = _urdfdom_error(lines)
    if error is not None or model is None:
        raise UrdfError(f"not a URDF Pinocchio reads ({error or failure})")
    return model
