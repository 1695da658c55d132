"""`rhmpc export`: the controller as a self-contained C library (OSQP codegen + the tick).

What is written to ``OUTDIR``::

    rhmpc.h          the API, units and array layouts (sizes baked in as macros)
    rhmpc.c          the per-tick logic of RecedingHorizonMPC.step (the output offset by forward
                     kinematics; the screening cascade: level 1 unconstrained minimiser, level 2
                     torque-box QP by active set; then vector update, shifted warm start, OSQP,
                     fallback chain plan → LQ → zero, torque clipping)
    rhmpc_data.h/.c  the numbers, as ``const`` arrays, from the controller's own CondensedQP:
                     F_ext = [F, f0] (p → q), the screening map Z = −P⁻¹[F, f0], the cascade's
                     W = P_zz⁻¹, H = P_zz, F_z and the envelope rows (dense), A, G, l0, u0,
                     the LQ gain, the one-tick shift (primal and dual), block of each tick, u_max,
                     the end-effector's kinematic chain (joint placements and axes, from the
                     robot's Pinocchio model)
    osqp/            OSQP's embedded code (``OSQP.codegen``, ``parameters="vectors"``), generated
                     from the controller's own solver object: P, A, settings and KKT factorisation
    CMakeLists.txt   builds librhmpc.a and librhmpc_shared.so

Everything numeric is read from a built :class:`RecedingHorizonMPC`, so the C code solves the
same QP as the Python controller; the equivalence tests compare the two tick for tick.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import tempfile
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from importlib.resources import files
from pathlib import Path

import numpy as np

from rhmpc.control.mpc import MPCStats, RecedingHorizonMPC
from rhmpc.control.settings import to_dict

#: Prefix of OSQP's generated globals (``rhmpc_osqp_solver``) and workspace files.
OSQP_PREFIX = "rhmpc_osqp_"
_WARM_STARTS = {"shift": 0, "shift_primal": 1, "keep": 2, "none": 3}
_TEMPLATES = ("rhmpc.h", "rhmpc.c", "rhmpc_data.h", "CMakeLists.txt")
#: Where the extra per-tick inputs come from (``rhmpc_extra_source()`` in C): constant zero (no
#: offset correction), forward kinematics in C (``rhmpc_offset``), or the caller.
EXTRA_SOURCES = ("zero", "fk", "caller")
#: Pinocchio joints the generated forward kinematics knows: revolute about x, y, z (code 0-2)
#: or about any unit axis (code 3).
_FK_JOINTS = {"JointModelRX": 0, "JointModelRY": 1, "JointModelRZ": 2,
              "JointModelRevoluteUnaligned": 3}


_EXTRA_DOC = {
    "zero": "{n} values, zero (no output offset correction)",
    "fk": ("{n} values, the output offset d = p(q0 + x_q) - (C x + y0) [m] of "
           "RecedingHorizonMPC.offset(x), computed by rhmpc_offset from x when extra is NULL"),
    "caller": ("{n} values, RecedingHorizonMPC.offset(x): the output offset "
               "d = p(q0 + x_q) - (C x + y0) [m], given by the caller (rhmpc_tick_ext)"),
}


class ExportError(ValueError):
    """The controller cannot be exported as it is configured (the message says why)."""


@dataclass(frozen=True)
class ExportInfo:
    """What :func:`export_controller` wrote.

    Attributes
    ----------
    outdir : Path
        The library's source directory (give it to ``cmake -S``).
    key : str
        Hash of everything the generated code depends on (QP data, settings, versions).
    files : tuple[str, ...]
        Files written, relative to ``outdir``.
    notes : tuple[str, ...]
        Settings the C code does not reproduce exactly (also written into ``rhmpc.h``).
    """

    outdir: Path
    key: str
    files: tuple[str, ...]
    notes: tuple[str, ...] = ()


def _version(name: str) -> str:
    try:
        return version(name)
    except PackageNotFoundError:
        return "unknown"


def _n_extra(mpc: RecedingHorizonMPC) -> int:
    """Per-tick inputs of p after [x; r_1..r_N; u_{−1}] (e.g. an output offset)."""
    qp = mpc.qp
    return qp.npar - (qp.nx + qp.N * qp.ny + qp.nu)


def _fk_chain(mpc: RecedingHorizonMPC) -> tuple[list, str | None]:
    """The joints from the root to the end-effector frame's joint (Pinocchio's JointModel
    objects), and None; or ``([], reason)`` if the generated kinematics cannot reproduce
    ``mpc.offset``."""
    robot = getattr(mpc.arm, "robot", None)
    if _n_extra(mpc) != mpc.ny or robot is None:
        return [], "the extra inputs are not an output offset of a known robot"
    model = robot.model
    joint = int(model.frames[robot.ee_frame_id].parentJoint)
    chain = []
    while joint > 0:
        chain.append(model.joints[joint])
        joint = int(model.parents[joint])
    chain.reverse()
    names = sorted({j.shortname() for j in chain} - set(_FK_JOINTS))
    if names or not chain or any(j.nq != 1 or j.idx_q >= mpc.nu for j in chain):
        return [], f"joints {', '.join(names) or '?'}: only revolute chains are generated"
    return chain, None


def extra_source(mpc: RecedingHorizonMPC) -> str:
    """Where the exported tick gets its extra per-tick inputs (one of :data:`EXTRA_SOURCES`)."""
    if _n_extra(mpc) == 0 or not mpc.settings.offset_correction:
        return "zero"
    return "fk" if _fk_chain(mpc)[1] is None else "caller"


def _offset_arrays(mpc: RecedingHorizonMPC) -> dict[str, tuple[np.ndarray, str]]:
    """The forward kinematics of ``mpc.offset`` as data for C's ``rhmpc_offset``: per joint
    of the chain (root first) its type (:data:`_FK_JOINTS`), q index, axis, and placement in
    its parent (rotation row-major, translation); the end-effector frame's translation in the
    last joint; and the output map C (row-major). Empty arrays if not generated."""
    chain = _fk_chain(mpc)[0] if extra_source(mpc) == "fk" else []
    model = mpc.arm.robot.model if chain else None
    types, iq, axes, rot, pos = [], [], [], [], []
    for j in chain:
        placement = model.jointPlacements[j.id]
        types.append(_FK_JOINTS[j.shortname()])
        iq.append(j.idx_q)
        axes.append(np.asarray(j.extract().axis) if types[-1] == 3 else np.eye(3)[types[-1]])
        rot.append(np.asarray(placement.rotation))
        pos.append(np.asarray(placement.translation))
    frame = (np.asarray(model.frames[mpc.arm.robot.ee_frame_id].placement.translation)
             if chain else np.zeros(3))
    return {
        "fk_type": (np.array(types, dtype=int), "int"),
        "fk_iq": (np.array(iq, dtype=int), "int"),
        "fk_axis": (np.array(axes, dtype=float).reshape(-1), "double"),
        "fk_R": (np.array(rot, dtype=float).reshape(-1), "double"),
        "fk_p": (np.array(pos, dtype=float).reshape(-1), "double"),
        "fk_frame_p": (frame.astype(float), "double"),
        "C": (np.asarray(mpc.arm.C, dtype=float), "double"),
    }


def _brakes(mpc: RecedingHorizonMPC) -> bool:
    """True if the controller's fallback chain has a braking step (then its LQ step is checked
    against the constraint rows): read from its statistics' fallback sources."""
    return "brake" in MPCStats().fallbacks


def _check(mpc: RecedingHorizonMPC) -> None:
    """Raise ExportError for what the generated code does not reproduce."""
    qp, s = mpc.qp, mpc.settings
    if _n_extra(mpc) < 0:
        raise ExportError(f"the QP has {qp.npar} parameters, fewer than x, ref and u_prev")
    if _n_extra(mpc) > 0 and not callable(getattr(mpc, "offset", None)):
        raise ExportError(f"the QP has {_n_extra(mpc)} per-tick inputs besides x, ref, u_prev "
                          "and the controller does not say how to compute them (offset(x))")
    unknown = set(MPCStats().fallbacks) - {"plan", "lq", "brake", "zero"}
    if unknown:
        raise ExportError(f"fallback source(s) {sorted(unknown)} are not exported yet")
    if s.adaptive_rho:
        raise ExportError("adaptive_rho needs OSQP's KKT refactorisation, which the vectors-mode "
                          "embedded code does not have; set mpc.adaptive_rho = false")
    if s.polish:
        raise ExportError("OSQP's embedded code does not polish; set mpc.polish = false")
    if s.warm_start not in _WARM_STARTS:
        raise ExportError(f"warm start {s.warm_start!r} is not exported")
    m, nv = qp.A.shape
    arrays = {"P": qp.P, "F": qp.F, "f0": qp.f0, "A": qp.A, "G": qp.G,
              "minimiser": qp.minimiser, "gain": qp.gain, "gain0": qp.gain0}
    for name, a in arrays.items():
        if not np.all(np.isfinite(a)):
            raise ExportError(f"the QP's {name} has non-finite entries")
    for name, a in (("l0", qp.l0), ("u0", qp.u0)):  # ±inf: a row bounded on one side only
        if np.any(np.isnan(a)):
            raise ExportError(f"the QP's {name} has NaN entries")
    if qp.shift.shape != (nv, nv) or qp.shift_dual.shape != (m, m):
        raise ExportError("unexpected shapes of the warm-start shift")


def _envelope_rows(mpc: RecedingHorizonMPC) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    F = np.asarray(mpc._F_z)

    def key(i: int) -> tuple:
        rc = np.flatnonzero(F[i, nx:nx + N * ny])
        return (tuple(sorted(set((rc % ny).tolist()))), int(rc[0]) if rc.size else N * ny, i)

    return np.array(sorted(range(F.shape[0]), key=key), dtype=int)


def _blocked_arrays(mpc: RecedingHorizonMPC) -> dict[str, tuple[np.ndarray, str]]:
    """The block-sparse maps of the screening cascade: F_z (q_z = F_z [p; 1]) and the distinct
    envelope rows' z part, as (array, C type) per name."""
    out: dict[str, tuple[np.ndarray, str]] = {}
    for name, blocked in (("F_z", _blocked(mpc._F_z, _q_row_order(mpc))),
                          ("A_env", _blocked(_envelope_rows(mpc)[0]))):
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
        "neg_W": _column_major(mpc.box._negW),
        "W": np.asarray(mpc.box.W),  # symmetric, read by rows
        "H": _column_major(mpc.box.H),
        "G_env_T": _column_major(_envelope_rows(mpc)[1]),
        "l0": np.asarray(qp.l0),
        "u0": np.asarray(qp.u0),
        "gain": np.asarray(qp.gain),
        "gain0": np.asarray(qp.gain0),
        "u_max": np.asarray(qp.u_max),
        "q0": np.asarray(mpc.arm.q0, dtype=float),
        "y0": np.asarray(mpc.arm.y0, dtype=float),
        "M0": np.asarray(mpc.arm.M0, dtype=float),
        # the dual the controller pairs with a primal plan in its warm starts
        "y_plan": np.asarray(getattr(mpc, "_y_zero", np.zeros(qp.A.shape[0])), dtype=float),
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


def export_key(mpc: RecedingHorizonMPC, robot: str) -> str:
    """Hash of the QP data, the settings and the versions the generated code depends on."""
    h = hashlib.sha256()
    meta = {"robot": robot, "settings": to_dict(mpc.settings), "rhmpc": _version("rhmpc"),
            "osqp": _version("osqp"), "Ts": float(mpc.arm.Ts)}
    h.update(json.dumps(meta, sort_keys=True).encode())
    qp = mpc.qp
    sparse = [getattr(qp, name) for name in _SPARSE]
    blocked = [v for v, _ in (*_blocked_arrays(mpc).values(), *_offset_arrays(mpc).values())]
    for a in (qp.P, *(_data_arrays(mpc).values()), *sparse, *blocked, qp.block_of_tick):
        h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    for name in _TEMPLATES:
        h.update(files(__package__).joinpath("templates", name).read_bytes())
    return h.hexdigest()[:16]


def export_controller(mpc: RecedingHorizonMPC, outdir: str | Path, *, robot: str) -> ExportInfo:
    """Write the C library of ``mpc`` (a freshly built or reset controller) to ``outdir``.

    Raises
    ------
    ExportError
        If the controller uses something the generated code does not reproduce.
    """
    _check(mpc)
    qp, s = mpc.qp, mpc.settings
    if not hasattr(mpc, "_osqp"):
        raise ExportError("the controller has no OSQP solver object to generate code from")
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    key = export_key(mpc, robot)
    notes = []
    if s.time_limit > 0:
        # OSQP 1.1's embedded sources have no timer (no timing.c; the generated workspace has
        # no timer object), so the wall-clock limit cannot be generated.
        notes.append(f"time_limit = {s.time_limit:g} s is not enforced in C (OSQP's embedded "
                     f"code has no timer); a solve is bounded by max_iter = {s.max_iter}")
    if extra_source(mpc) == "caller":
        notes.append(f"the output offset's forward kinematics ({_fk_chain(mpc)[1]}); "
                     "the caller gives it to rhmpc_tick_ext")
    subs = {
        "ROBOT": robot, "ROBOT_ID": "".join(c if c.isalnum() else "_" for c in robot),
        "HASH": key, "VERSION": _version("rhmpc"), "OSQP_VERSION": _version("osqp"),
        "TS_US": f"{mpc.arm.Ts * 1e6:g}", "TS": repr(float(mpc.arm.Ts)),
        "N": qp.N, "NX": qp.nx, "NU": qp.nu, "NY": qp.ny,
        "NV": qp.P.shape[0], "NZ": int(qp.nz), "M": qp.A.shape[0], "NPAR": qp.npar,
        "NEXTRA": _n_extra(mpc), "NENV_U": len(_envelope_rows(mpc)[0]),
        "EXTRA_SOURCE": EXTRA_SOURCES.index(extra_source(mpc)),
        "FK_JOINTS": len(_offset_arrays(mpc)["fk_type"][0]),
        "NBC": len(qp.bound_columns),
        "EXTRA_DOC": _EXTRA_DOC[extra_source(mpc)].format(n=_n_extra(mpc)),
        "BRAKE": int(_brakes(mpc)), "BRAKE_TICKS": s.block_lengths[0],
        "LQ_DOC": ("used only if its clipped plan keeps every constraint row, else the braking "
                   "torque -M0 qdot / (RHMPC_BRAKE_TICKS Ts), clipped" if _brakes(mpc) else
                   "clipped to +-u_max"),
        "PLAN_FALLBACK_TICKS": s.plan_fallback_ticks, "MAX_ITER": s.max_iter,
        "WARM_START": _WARM_STARTS[s.warm_start], "WARM_START_NAME": s.warm_start,
        "SCREENING": int(s.screening), "PARAM_BOUNDS": int(qp.param_bounds),
        "BOX_SCREENING": int(s.box_screening), "BOX_MAX_ITER": mpc.box.settings.max_iter,
        "BOX_PDAS_ITER": mpc.box.settings.pdas_iter,
        "BOX_PRIMAL_TOL": repr(float(mpc.box.settings.primal_tol)),
        "BOX_DUAL_TOL": repr(float(mpc.box.settings.dual_tol)),
        "BOX_KKT_TOL": repr(float(mpc.box.settings.kkt_tol)),
        "OSQP_PREFIX": OSQP_PREFIX,
        "NOTES": "".join(f"\n * Not exported: {n}." for n in notes) or "\n * (Nothing left out.)",
    }
    written = []
    for name in _TEMPLATES:
        text = files(__package__).joinpath("templates", name).read_text()
        for k, v in subs.items():
            text = text.replace(f"@{k}@", str(v))
        leftover = re.search(r"@[A-Z_]+@", text)
        if leftover:
            raise RuntimeError(f"template {name}: unreplaced placeholder {leftover.group()}")
        (outdir / name).write_text(text)
        written.append(name)

    data = _data_arrays(mpc)
    parts = [f"/* Generated by `rhmpc export` (robot \"{robot}\", hash {key}): the controller's "
             "numbers, from its CondensedQP. Row-major. */\n"
             "#include \"rhmpc_data.h\"\n#include <math.h>\n\n"]
    for name, values in data.items():
        parts.append(_c_array(name, values))
    for name in _SPARSE:
        ptr, col, val = _csr(getattr(qp, name))
        parts += [_c_array(f"{name}_p", ptr, ctype="int"), _c_array(f"{name}_i", col, ctype="int"),
                  _c_array(f"{name}_x", val)]
    parts.append(_c_array("block_of_tick", qp.block_of_tick, ctype="int"))
    parts.append(_c_array("bound_columns", qp.bound_columns, ctype="int"))
    for name, (values, ctype) in (*_blocked_arrays(mpc).items(), *_offset_arrays(mpc).items()):
        parts.append(_c_array(name, values, ctype=ctype))
    parts.append(_c_array("env_row", _envelope_rows(mpc)[2], ctype="int"))
    (outdir / "rhmpc_data.c").write_text("".join(parts))
    written.append("rhmpc_data.c")

    osqp_dir = outdir / "osqp"
    if osqp_dir.exists():
        shutil.rmtree(osqp_dir)
    with tempfile.TemporaryDirectory() as tmp:
        solver = mpc._osqp  # the controller's own solver: same P, A, settings
        solver.codegen(
            str(Path(tmp) / "osqp"), parameters="vectors", extension_name=None,
            force_rewrite=True, prefix=OSQP_PREFIX,
        )
        shutil.copytree(Path(tmp) / "osqp", osqp_dir)
    for leftover in ("emosqp.c", "Makefile"):  # OSQP's example program (printf, main)
        (osqp_dir / leftover).unlink(missing_ok=True)
    written += sorted(str(p.relative_to(outdir)) for p in osqp_dir.rglob("*") if p.is_file())
    return ExportInfo(outdir=outdir, key=key, files=tuple(written), notes=tuple(notes))
