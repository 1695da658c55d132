"""The controller's numbers as C: ``rhmpc_data.c``, every array of the MPC and of the
controller as a ``const`` array (row-major; the dense maps also column-major and blocked for the
tick's mat-vecs), each double written as the shortest literal that reads back the same.
"""

from __future__ import annotations

import numpy as np

from rhmpc.control.mpc import RecedingHorizonMPC

__all__ = ["ExportError", "controller_arrays", "data_source", "envelope_rows"]


class ExportError(ValueError):
    """The controller cannot be exported as it is configured (the message says why)."""


def envelope_rows(mpc: RecedingHorizonMPC) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The envelope rows' distinct (z part of A, G on the bound columns) pairs: an upper and a
    lower row of a limit differ only in their slack's sign and bounds. Returns (A_u (n_u, nz),
    G_u (n_u, nbc), row → distinct-row index (m − nv,)), distinct rows in order of appearance.
    """
    qp = mpc.qp
    nv, nz = qp.nv, qp.nz
    if np.any(qp.G[:nv]):
        raise ExportError("the QP's torque or slack rows depend on the parameters; the generated "
                          "code assumes constant torque and slack bounds")
    rows = np.hstack([qp.A[nv:, :nz], qp.G[nv:][:, qp.bound_columns]])
    if rows.shape[0] == 0:
        return np.zeros((0, nz)), np.zeros((0, len(qp.bound_columns))), np.zeros(0, dtype=int)
    _, first, inverse = np.unique(rows, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # distinct rows in order of first appearance
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    distinct = rows[np.sort(first)]
    return distinct[:, :nz], distinct[:, nz:], rank[np.ravel(inverse)]


def _column_major(M: np.ndarray) -> np.ndarray:
    """M (rows, cols) as C's ``matvec_cm`` reads it: column after column, each zero-padded to a
    multiple of 8 entries (so that every block of 8 rows is full)."""
    M = np.asarray(M, dtype=float)
    rows = -(-M.shape[0] // 8) * 8
    out = np.zeros((M.shape[1], rows))
    out[:, : M.shape[0]] = M.T
    return out


def _blocked(M: np.ndarray, perm: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """M (rows, cols) for C's ``matvec_blocks``: its rows reordered by ``perm``, column-major
    and padded (:func:`_column_major`), with each block of 8 rows' non-zero columns listed
    (``cptr``, ``cols``: all-zero columns of a block are skipped; adding 0 changes no sum, so the
    result is the same to the bit). ``out[perm[r]]`` receives row r of the reordered matrix."""
    M = np.asarray(M, dtype=float)
    rows = M.shape[0]
    perm = np.arange(rows) if perm is None else np.asarray(perm, dtype=int)
    Mp = M[perm]
    cptr, cols = [0], []
    for r0 in range(0, rows, 8):
        cols.extend(np.flatnonzero(np.any(Mp[r0:r0 + 8] != 0, axis=0)).tolist())
        cptr.append(len(cols))
    return {"T": _column_major(Mp), "cptr": np.array(cptr), "cols": np.array(cols, dtype=int),
            "perm": perm}


def _q_row_order(mpc: RecedingHorizonMPC) -> np.ndarray:
    """Rows of F_z grouped by the reference axes they read, then by their first reference
    point: a joint moves only some end-effector axes at q0 and a block only the points after
    its start, so blocks of 8 such rows share many all-zero columns (measured on the PHANToM:
    48 % of the block columns skipped against 26 % in the natural order)."""
    qp = mpc.qp
    nx, N, ny = qp.nx, qp.N, qp.ny
    F = np.asarray(mpc.F_z)

    def key(i: int) -> tuple:
        rc = np.flatnonzero(F[i, nx:nx + N * ny])
        return (tuple(sorted(set((rc % ny).tolist()))), int(rc[0]) if rc.size else N * ny, i)

    return np.array(sorted(range(F.shape[0]), key=key), dtype=int)


def _blocked_arrays(mpc: RecedingHorizonMPC) -> dict[str, tuple[np.ndarray, str]]:
    """The block-sparse maps of the screening cascade: F_z (q_z = F_z [p; 1]) and the distinct
    envelope rows' z part, as (array, C type) per name."""
    out: dict[str, tuple[np.ndarray, str]] = {}
    for name, blocked in (("F_z", _blocked(mpc.F_z, _q_row_order(mpc))),
                          ("A_env", _blocked(envelope_rows(mpc)[0]))):
        for part, values in blocked.items():
            out[f"{name}_{part}"] = (values, "double" if part == "T" else "int")
    return out


def _data_arrays(mpc: RecedingHorizonMPC) -> dict[str, np.ndarray]:
    """The const arrays of rhmpc_data.c, row-major, from the controller's CondensedQP."""
    qp = mpc.qp
    return {
        "F_ext": np.column_stack([qp.F, qp.f0]),
        "minimiser": np.asarray(qp.minimiser),
        # the screening cascade (levels 1 and 2), column-major: the controller's own arrays
        "neg_W": _column_major(-mpc.W),
        "W": np.asarray(mpc.W),  # symmetric, read by rows
        "H": _column_major(mpc.hessian),
        "G_env_T": _column_major(envelope_rows(mpc)[1]),
        "l0": np.asarray(qp.l0),
        "u0": np.asarray(qp.u0),
        "gain": np.asarray(qp.gain),
        "gain0": np.asarray(qp.gain0),
        "u_max": np.asarray(qp.u_max),
        "M0": np.asarray(mpc.arm.M0, dtype=float),
        # the dual the controller pairs with a primal plan in its warm starts
        "y_plan": np.asarray(mpc.y_plan, dtype=float),
    }


def _c_double(v: float) -> str:
    """A C literal that reads back as the same double (Python's repr round-trips)."""
    v = float(v)
    if np.isinf(v):
        return "HUGE_VAL" if v > 0 else "-HUGE_VAL"
    return repr(v)


def _c_array(name: str, values: np.ndarray, ctype: str = "double") -> str:
    flat = np.ascontiguousarray(values, dtype=float if ctype == "double" else np.int64).ravel()
    # repr of a Python float is the shortest string that round-trips: the C compiler reads back
    # the same double.
    if not np.any(flat):  # e.g. G without joint bounds: C zero-fills the rest
        return f"const {ctype} rhmpc_{name}[{max(flat.size, 1)}] = {{0}};\n"
    items = [_c_double(v) if ctype == "double" else str(int(v)) for v in flat]
    lines = [", ".join(items[i:i + 6]) for i in range(0, len(items), 6)]
    body = ",\n  ".join(lines)
    return f"const {ctype} rhmpc_{name}[{len(items)}] = {{\n  {body}\n}};\n"


#: Matrices written in CSR form (mostly zeros: identity rows, a few parameter columns).
_SPARSE = ("A", "G", "shift", "shift_dual")


def _csr(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(row pointers, column indices, values) of the non-zero entries, row after row."""
    values = np.asarray(values, dtype=float)
    rows, cols = np.nonzero(values)
    ptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=values.shape[0]))])
    return ptr, cols, values[rows, cols]


def controller_arrays(controller) -> dict[str, np.ndarray]:
    """The observer's matrices, the torque and joint limits, q0, y0 and the output map C
    (y = C x + y0)."""
    arm, n = controller.mpc.arm, controller.nu
    robot = getattr(arm, "robot", None)
    lower, upper = (robot.position_limits if robot is not None
                    else (np.full(n, -np.inf), np.full(n, np.inf)))
    observer = controller.observer  # both steps as one mat-vec each, on [x; q; 1], [x; u; 1]:
    L, q0 = observer.L, np.asarray(arm.q0, dtype=float)  # x = [I − L H, L, −L q0] [x⁻; q; 1]
    correct = np.hstack([np.eye(2 * n) - np.hstack([L, np.zeros((2 * n, n))]), L,
                         -(L @ q0)[:, None]])
    predict = np.hstack([observer.A, observer.B, np.zeros((2 * n, 1))])  # x⁻ = A x + B u
    return {"correct": correct, "predict": predict,
            "tau_max": controller.torque_limit, "q0": np.asarray(arm.q0, dtype=float),
            "q_min": lower, "q_max": upper,
            "gate": np.asarray(controller.observer.gate, dtype=float),
            "y0": np.asarray(arm.y0, dtype=float), "output": np.asarray(arm.C, dtype=float)}


def data_source(controller, robot: str, key: str) -> str:
    """rhmpc_data.c: every array of the MPC and of the controller."""
    mpc = controller.mpc
    qp = mpc.qp
    parts = [f"/* Generated by `rhmpc export` (robot \"{robot}\", hash {key}): the controller's "
             "numbers. Row-major. */\n#include \"rhmpc_data.h\"\n#include <math.h>\n\n"]
    for name, values in (*_data_arrays(mpc).items(), *controller_arrays(controller).items()):
        parts.append(_c_array(name, values))
    for name in _SPARSE:
        ptr, col, val = _csr(getattr(qp, name))
        parts += [_c_array(f"{name}_p", ptr, ctype="int"), _c_array(f"{name}_i", col, ctype="int"),
                  _c_array(f"{name}_x", val)]
    parts.append(_c_array("block_of_tick", qp.block_of_tick, ctype="int"))
    parts.append(_c_array("bound_columns", qp.bound_columns, ctype="int"))
    for name, (values, ctype) in _blocked_arrays(mpc).items():
        parts.append(_c_array(name, values, ctype=ctype))
    parts.append(_c_array("env_row", envelope_rows(mpc)[2], ctype="int"))
    return "".join(parts)
