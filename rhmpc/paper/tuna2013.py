"""The published cells of Tuna et al. (T-RO 2013), Tables I–III.

Table I: simulation ("a linearized, reduced order model of the actual hardware", §VIII-B);
Tables II–III: experiments on a PHANToM Premium 1.5A at 2 kHz, the error "calculated from the
difference between the prerecorded target point and the actual end-effector position calculated
from joint angles" (§VIII-A); Table III adds the EKF to Table II(a)'s rows. Every published
cell is the maximum over ten runs, whose "deviation ... had been very small" (§VIII-B).
Columns: fixed heart rate, animals 1 and 2 (top); varying, animals 1 and 3 (top), animals 1 and
3 (side) — the scenarios ``fixed-a1-top`` … ``varying-a3-side`` replicate them.
"""

from __future__ import annotations

#: Column order of the tables (scenario names of the replicas).
COLUMNS = ("fixed-a1-top", "fixed-a2-top", "varying-a1-top", "varying-a3-top",
           "varying-a1-side", "varying-a3-side")


def _row(*values: float) -> dict[str, float]:
    return dict(zip(COLUMNS, values, strict=True))


#: (table, metric) → predictor → scenario → published value (mm or mN·m).
TUNA2013: dict[tuple[str, str], dict[str, dict[str, float]]] = {
    ("I", "rms_error_mm"): {
        "exact": _row(0.488, 0.237, 0.231, 0.197, 0.194, 0.231),
        "one-step": _row(0.524, 0.255, 0.247, 0.206, 0.201, 0.237),
        "generalized": _row(0.481, 0.235, 0.229, 0.195, 0.191, 0.230),
    },
    ("I", "max_error_mm"): {
        "exact": _row(1.428, 1.236, 0.777, 0.650, 1.542, 1.033),
        "one-step": _row(1.953, 1.460, 1.098, 0.917, 2.163, 1.195),
        "generalized": _row(1.399, 1.173, 0.767, 0.861, 1.540, 1.059),
    },
    ("I", "rms_effort_mNm"): {
        "exact": _row(18.873, 14.589, 16.647, 11.719, 13.675, 14.137),
        "one-step": _row(26.685, 21.801, 37.991, 18.010, 30.402, 20.027),
        "generalized": _row(19.865, 17.294, 16.786, 12.242, 13.840, 13.909),
    },
    ("II", "rms_error_mm"): {
        "exact": _row(0.344, 0.162, 0.163, 0.171, 0.161, 0.165),
        "one-step": _row(0.404, 0.176, 0.181, 0.199, 0.173, 0.188),
        "generalized": _row(0.351, 0.174, 0.168, 0.178, 0.164, 0.167),
    },
    ("II", "max_error_mm"): {
        "exact": _row(1.238, 0.912, 0.780, 0.559, 0.538, 0.906),
        "one-step": _row(2.236, 1.395, 1.576, 1.084, 0.960, 1.022),
        "generalized": _row(1.291, 1.022, 0.827, 0.615, 0.572, 0.972),
    },
    ("II", "rms_effort_mNm"): {
        "exact": _row(54.379, 28.512, 25.350, 21.593, 24.390, 27.260),
        "one-step": _row(55.686, 33.785, 46.820, 24.346, 52.640, 29.592),
        "generalized": _row(54.948, 29.699, 25.760, 22.082, 24.635, 27.830),
    },
    ("III", "rms_error_mm"): {"ekf": _row(1.148, 0.386, 0.515, 0.523, 0.433, 0.449)},
    ("III", "max_error_mm"): {"ekf": _row(5.157, 2.863, 3.006, 2.859, 2.475, 2.796)},
}

#: Tuna's setting of each table: simulation or hardware.
SETTING = {"I": "simulation", "II": "hardware", "III": "hardware"}
