"""The comparison table: predictors × scenarios, with ratios to the exact row."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def comparison_table(docs: Sequence[dict], predictors: Sequence[str],
                     scenarios: Sequence[str]) -> str:
    """Tuna Tables I/III replica: RMS (max) error [mm] and RMS effort [mN·m] with ratios to exact.

    Each cell is the mean over the seeds that were run (a run that failed shows as ``failed``).
    """
    def cell(pred: str, scen: str) -> dict | None:
        rows = [d for d in docs if d.get("predictor") == pred and d.get("scenario") == scen
                and "rms_error_mm" in d]
        if not rows:
            return None
        return {k: float(np.mean([r[k] for r in rows]))
                for k in ("rms_error_mm", "max_error_mm", "rms_effort_mNm")}

    width = 17
    head = f"{'':<13}" + "".join(f"{s:>{width}}" for s in scenarios)
    out = ["RMS position error [mm] (maximum error [mm])", head]
    for pred in predictors:
        row = f"{pred:<13}"
        for scen in scenarios:
            c = cell(pred, scen)
            row += f"{'failed':>{width}}" if c is None else \
                f"{c['rms_error_mm']:>8.3f} ({c['max_error_mm']:5.3f})".rjust(width)
        out.append(row)
    out += ["", "RMS control effort [mN·m]", head]
    for pred in predictors:
        row = f"{pred:<13}"
        for scen in scenarios:
            c = cell(pred, scen)
            row += f"{'failed':>{width}}" if c is None else f"{c['rms_effort_mNm']:>{width}.2f}"
        out.append(row)
    if "exact" in predictors:
        out += ["", "ratio to exact: RMS error / RMS effort", head]
        for pred in predictors:
            if pred == "exact":
                continue
            row = f"{pred:<13}"
            for scen in scenarios:
                c, e = cell(pred, scen), cell("exact", scen)
                if c is None or e is None:
                    row += f"{'-':>{width}}"
                else:
                    ratio = (f"{c['rms_error_mm'] / e['rms_error_mm']:.2f} / "
                             f"{c['rms_effort_mNm'] / e['rms_effort_mNm']:.2f}")
                    row += ratio.rjust(width)
            out.append(row)
    return "\n".join(out)
