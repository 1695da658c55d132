"""The comparison table: predictors × scenarios, with ratios to the exact row."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def comparison_table(docs: Sequence[dict], predictors: Sequence[str],
                     scenarios: Sequence[str]) -> str:
    """Tuna Tables I/III replica: RMS (max) error [mm] and RMS effort [mN·m] with ratios to exact.

    One column per scenario (or recording: the documents' ``scenario``). Each cell is the mean
    over the seeds that were run (a run that failed shows as ``failed``). The ratios are to
    the ``exact`` row, or to ``hold`` when ``exact`` was not run.
    """
    def cell(pred: str, scen: str) -> dict | None:
        rows = [d for d in docs if d.get("predictor") == pred and d.get("scenario") == scen
                and "rms_error_mm" in d]
        if not rows:
            return None
        return {k: float(np.mean([r[k] for r in rows]))
                for k in ("rms_error_mm", "max_error_mm", "rms_effort_mNm")}

    width = max(17, *(len(s) + 2 for s in scenarios))
    head = f"{'':<13}" + "".join(f"{s:>{width}}" for s in scenarios)

    def block(title: str, text) -> list[str]:
        lines = ["", title, head]
        for pred in predictors:
            cells = [cell(pred, scen) for scen in scenarios]
            lines.append(f"{pred:<13}" + "".join(
                f"{'failed':>{width}}" if c is None else text(c).rjust(width) for c in cells))
        return lines

    out = block("RMS position error [mm] (maximum error [mm])",
                lambda c: f"{c['rms_error_mm']:>8.3f} ({c['max_error_mm']:5.3f})")[1:]
    out += block("RMS control effort [mN·m]", lambda c: f"{c['rms_effort_mNm']:.2f}")
    ref = next((p for p in ("exact", "hold") if p in predictors), None)
    if ref is not None:
        out += ["", f"ratio to {ref}: RMS error / RMS effort", head]
        for pred in predictors:
            if pred == ref:
                continue
            row = f"{pred:<13}"
            for scen in scenarios:
                c, e = cell(pred, scen), cell(ref, scen)
                if c is None or e is None:
                    row += f"{'-':>{width}}"
                else:
                    ratio = (f"{c['rms_error_mm'] / e['rms_error_mm']:.2f} / "
                             f"{c['rms_effort_mNm'] / e['rms_effort_mNm']:.2f}")
                    row += ratio.rjust(width)
            out.append(row)
    return "\n".join(out)
