"""What the generated C and its binding share, written once: the names of the status codes, the
torque's sources and the reference's events, and the layout of ``rhmpc_public_t``.

``rhmpc.h`` takes its enums and the public struct from here, ``rhmpc.c`` its name tables, and
:mod:`.binding` its names and its ``ctypes`` mirror of the struct.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass, field

#: ``enum rhmpc_status``: (C name, the name of Python's ``MPCStats.failures``, comment).
STATUS = (
    ("SOLVED", "solved", ""), ("NONFINITE_INPUT", "nonfinite_input", ""),
    ("NONFINITE_SOLUTION", "nonfinite_solution", ""), ("SOLVER_ERROR", "solver_error", ""),
    ("INJECTED", "injected", ""), ("SOLVED_INACCURATE", "solved_inaccurate", ""),
    ("PRIMAL_INFEASIBLE", "primal_infeasible", ""), ("DUAL_INFEASIBLE", "dual_infeasible", ""),
    ("MAX_ITER_REACHED", "max_iter", ""), ("TIME_LIMIT", "time_limit", ""),
    ("NON_CONVEX", "non_convex", ""), ("INTERRUPTED", "interrupted", ""),
    ("UNSOLVED", "unsolved", ""),
    ("BOX_CAPPED", "box_max_iter", "level 2 reached its cap: the fallback at once"),
    ("BACKOFF", "backoff", "levels 2-3 rest after failed ticks"),
    ("ENCODER_FAULT", "encoder_fault", "the encoders' reading held out too long: brake"),
)
#: ``enum rhmpc_source``: where the MPC torque of a tick came from.
SOURCES = ("qp", "plan", "lq", "brake", "zero")
#: ``enum rhmpc_count``: the reference's and the predictor's events (Python's counts' names).
COUNTS = ("updates", "missing", "outliers_rejected", "gate_unlocked", "retracted",
          "forecast_clamped", "forecast_nonfinite", "rls_reset", "rls_bound", "reference_guard",
          "repaired", "forecast_capped", "external", "external_rejected", "external_stale")
STATUS_NAMES = tuple(python for _, python, _ in STATUS)


@dataclass
class MPCStats:
    """What the controller did: the last tick, and counters since construction or reset.

    Attributes
    ----------
    ticks : int
        Number of steps.
    status : str
        Last tick: ``"solved"`` or the failure reason (an OSQP status such as ``"max_iter"``,
        ``"time_limit"``, ``"primal_infeasible"``, or ``"nonfinite_input"``,
        ``"nonfinite_solution"``, ``"solver_error"``, ``"injected"``).
    source : str
        Where the last torque came from: ``"qp"``, ``"plan"``, ``"lq"``, ``"brake"``, ``"zero"``.
    iterations : int
        OSQP iterations of the last tick (0 if no solve ran).
    screened : int
        Ticks solved by level 1 of the screening cascade (the unconstrained minimiser holds
        every row), without calling the solver (their ``source`` is ``"qp"``).
    boxed : int
        Ticks solved by level 2 (the torque-box QP by active set, every envelope row holding:
        :mod:`rhmpc.control.mpc`), without calling the solver (``source`` ``"qp"``).
    level : int
        Last tick: the cascade level that produced the QP solution (1, 2, or 3 = OSQP), 0 if
        the tick never reached the QP (non-finite inputs).
    box_iterations : int
        Last tick: level 2's active-set solves (also when it was tried and the tick went on to
        level 3), else 0.
    solve_time : float
        Wall time of the last ``solve()`` call [s].
    parts_ns : list[int]
        Last tick's phases [ns]: reference handling (incl. the offset), vector update (incl. warm
        start), OSQP solve, output (status check, clipping, bookkeeping).
    failures : dict[str, int]
        Ticks whose QP result was not used, by reason.
    fallbacks : dict[str, int]
        Ticks served by each fallback: ``"plan"``, ``"lq"``, ``"brake"``, ``"zero"``.
    relaxed : int
        Solved ticks whose plan relaxes the envelope (some slack above 0.01 of its unit, i.e.
        0.01 % of a joint range or 1 µm Cartesian): the soft constraints were needed.
    slack_max : float
        Largest slack of a solved tick [units of :mod:`rhmpc.control.envelope`].
    """

    ticks: int = 0
    status: str = "none"
    source: str = "none"
    iterations: int = 0
    screened: int = 0
    boxed: int = 0
    level: int = 0
    box_iterations: int = 0
    solve_time: float = 0.0
    parts_ns: list[int] = field(default_factory=lambda: [0, 0, 0, 0])
    failures: dict[str, int] = field(default_factory=dict)
    fallbacks: dict[str, int] = field(default_factory=lambda: dict.fromkeys(SOURCES[1:], 0))
    relaxed: int = 0
    slack_max: float = 0.0

    @property
    def fallback_total(self) -> int:
        """Ticks that did not apply the QP solution."""
        return sum(self.fallbacks.values())


#: ``rhmpc_public_t``: (field, C type, length as (dimension, factor) or None, comment).
PUBLIC = (
    ("ticks", "long long", None, "rhmpc_step calls since rhmpc_init"),
    ("screened", "long long", None, "ticks solved by level 1 (screening), without OSQP"),
    ("boxed", "long long", None, "ticks solved by level 2 (the torque-box QP)"),
    ("failures", "long long", ("N_STATUS", 1), "ticks whose QP result was not used, by status"),
    ("fallbacks", "long long", ("N_SOURCES", 1), "ticks served by each source; [0] (QP) stays 0"),
    ("counts", "long long", ("N_COUNTS", 1), "the reference's events (enum rhmpc_count)"),
    ("status", "int", None, "the last step's enum rhmpc_status"),
    ("source", "int", None, "enum rhmpc_source"),
    ("iterations", "int", None, "OSQP iterations (0: screened or no solve)"),
    ("level", "int", None, "cascade level: 1 screened, 2 box QP, 3 OSQP; 0 none"),
    ("box_iterations", "int", None, "level 2's active-set solves in the last step"),
    ("saturated", "int", None, "the last step's torque was clipped"),
    ("step_ns", "long long", None, "the last step's duration [ns], CLOCK_MONOTONIC"),
    ("refresh_ns", "long long", None, "the last refresh's or forecast's duration [ns]"),
    ("x_hat", "double", ("NX", 1), "the last step's state estimate [q - q0; qdot]"),
    ("u", "double", ("NU", 1), "its MPC torque [N*m]"),
    ("tau_command", "double", ("NU", 1), "u plus the cancellation, before the clip [N*m]"),
    ("tau", "double", ("NU", 1), "the torque returned [N*m]"),
    ("first", "long long", None, "the tick of points[0]"),
    ("points", "double", ("SPAN", 3), "the last refresh's reference points [m]"),
    ("gate_floor", "double", None, "the outlier gate's floor [m] (NaN: calibrating)"),
    ("gate_locked", "int", None, "the gate's state"),
    ("ready", "int", None, "the predictor's state"),
    ("age_sum", "double", None, "sum of (tick Ts - stamp) over the forecasts [s]"),
    ("age_count", "long long", None, "forecasts made from a sample"),
    ("encoder_held", "long long", None, "encoder readings the observer held out"),
    ("encoder_reacquired", "long long", None, "held readings taken again once they moved"),
    ("fused", "long long", None, "the tick of the newest encoder reading taken (-1: none yet)"),
)
_CTYPES = {"long long": ctypes.c_longlong, "int": ctypes.c_int, "double": ctypes.c_double}
#: ``rhmpc_retract_t``: the call the outlier gate makes to retract a predictor's newest sample.
RETRACT = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p)


def _enum(names, comments=None) -> str:
    comments = comments or [""] * len(names)
    return "\n".join(f"  RHMPC_{n}{' = 0' if i == 0 else ''},{f' /* {c} */' if c else ''}"
                     for i, (n, c) in enumerate(zip(names, comments, strict=True)))


def _names(names) -> str:
    return ", ".join(f'"{n}"' for n in names)


def template_subs() -> dict[str, str]:
    """The placeholders of ``rhmpc.h`` and ``rhmpc.c`` made from the lists above."""
    fields = []
    for name, ctype, length, comment in PUBLIC:
        size = "" if length is None else f"[RHMPC_{length[0]}{f' * {length[1]}' * (length[1] > 1)}]"
        fields.append(f"  {ctype} {name}{size}; /* {comment} */")
    return {"STATUS_ENUM": _enum([c for c, _, _ in STATUS], [m for _, _, m in STATUS]),
            "SOURCE_ENUM": _enum([f"SOURCE_{s.upper()}" for s in SOURCES]),
            "COUNT_ENUM": _enum([c.upper() for c in COUNTS]),
            "PUBLIC_FIELDS": "\n".join(fields), "STATUS_NAMES": _names(STATUS_NAMES),
            "SOURCE_NAMES": _names(SOURCES), "COUNT_NAMES": _names(COUNTS)}


def public_struct(dims: dict[str, int]) -> type[ctypes.Structure]:
    """``rhmpc_public_t`` as a ``ctypes`` structure, for a library of these dimensions."""
    fields = []
    for name, ctype, length, _ in PUBLIC:
        kind = _CTYPES[ctype]
        fields.append((name, kind if length is None else kind * (dims[length[0]] * length[1])))

    class Public(ctypes.Structure):
        _fields_ = tuple(fields)

    return Public
