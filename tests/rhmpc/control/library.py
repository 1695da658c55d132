"""The tests' ways into the controller's library, and their references built apart from it.

The library (:class:`rhmpc.control.controller.Controller`) is built once per distinct
description and cached; :func:`mpc_library` builds one whose MPC a test calls alone
(``mpc_step``). The references: the QP's vectors and unconstrained input rebuilt from the QP's
data with the forward kinematics of an independent robot instance, and the QP solved exactly by
DAQP (dual active set; Arnström, Bemporad & Axehill, IEEE TAC 67(8), 2022).
"""

from __future__ import annotations

import daqp
import numpy as np

from rhmpc.bench.ticks import bench_controller
from rhmpc.control.settings import MPCSettings
from rhmpc.robots import load_robot

_FK = {}


def mpc_library(arm, settings: MPCSettings | None = None, u_prev=None):
    """The controller library of ``settings`` on ``arm`` (:func:`bench_controller`), reset, with
    u_{−1} = ``u_prev`` (default 0)."""
    controller = bench_controller(arm, settings or MPCSettings())
    if u_prev is not None:
        controller.take_over(u_prev)
    return controller


def offset(arm, x) -> np.ndarray:
    """d = p(q0 + x_q) − (C x + y0) by the forward kinematics of a robot loaded apart [m]."""
    name = arm.robot.name
    if name not in _FK:
        _FK[name] = load_robot(name).ee_position
    return _FK[name](arm.q0 + x[: arm.nu]) - (arm.C @ x + arm.y0)


def params(mpc, x, ref, u_prev=None) -> np.ndarray:
    """p = [x; r_1..r_N; u_{−1}; d(x)] of the QP the controller solves (d = 0 without
    ``offset_correction``)."""
    x = np.asarray(x, dtype=float)
    d = offset(mpc.arm, x) if mpc.settings.offset_correction else None
    u_prev = np.zeros(mpc.nu) if u_prev is None else np.asarray(u_prev, dtype=float)
    return mpc.qp.params(x, np.asarray(ref, dtype=float), u_prev, d)


def qp_vectors(mpc, x, ref, u_prev=None):
    """(q, l, u) of the QP the controller solves for ``x``, ``ref`` (P, A: ``mpc.qp``)."""
    p = params(mpc, x, ref, u_prev)
    return (mpc.qp.q(p), *mpc.qp.bounds(p))


def unconstrained(mpc, x, ref, u_prev=None) -> np.ndarray:
    """The first input of the unconstrained minimiser, not clipped [N·m]."""
    return mpc.qp.gain @ params(mpc, x, ref, u_prev) + mpc.qp.gain0


def daqp_solve(mpc, q, lower, upper) -> tuple[np.ndarray, np.ndarray]:
    """The QP's exact solution and multipliers (the first nv rows of A, the identity, as DAQP's
    simple bounds; the envelope rows as its general constraints)."""
    qp = mpc.qp
    x, _, flag, info = daqp.solve(qp.P, q, np.ascontiguousarray(qp.A[qp.nv:]),
                                  np.minimum(upper, 1e30), np.maximum(lower, -1e30))
    assert flag == 1, flag
    return x, np.asarray(info["lam"], dtype=float)


def daqp_input(mpc, x, ref, u_prev=None) -> np.ndarray:
    """The first input of the QP's exact solution, clipped to ±u_max [N·m]."""
    z, _ = daqp_solve(mpc, *qp_vectors(mpc, x, ref, u_prev))
    return np.clip(z[: mpc.nu] * mpc.u_max, -mpc.u_max, mpc.u_max)
