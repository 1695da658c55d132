"""The report of a synthetic prediction study (:func:`rhmpc.openloop.studies.run_study`'s
result): its text table and its figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rhmpc import io

__all__ = ["format_table", "plot_study"]

_PARAM_LABEL = {"noise": "σ_R [mm]", "hr-step": "ΔHR [bpm]", "rr": "record", "horizon": "lead [ms]"}


def format_table(result: dict) -> str:
    """Mean RMS error [mm] over trials: one row per parameter value, one column per predictor."""
    study, rows = result["study"], result["rows"]
    names = list(dict.fromkeys(r["predictor"] for r in rows))
    w = max(11, *(len(n) + 1 for n in names))
    lines = []
    if study == "horizon":
        for scn in dict.fromkeys(r["parameter"] for r in rows):
            sub = {r["predictor"]: r for r in rows if r["parameter"] == scn}
            lines.append(f"{scn}: RMS prediction error [mm] vs lead time")
            lines.append(f"{'lead [ms]':>10}" + "".join(f"{n:>{w}}" for n in names))
            for k, lead in enumerate(sub[names[0]]["lead_ms"]):
                lines.append(
                    f"{lead:>10.1f}" + "".join(f"{sub[n]['rms_mm'][k]:>{w}.3f}" for n in names)
                )
            hr = [
                f"{n} {sub[n]['hr_err_bpm_rms']:.1f} (max {sub[n]['hr_err_bpm_max']:.1f})"
                for n in names
                if "hr_err_bpm_rms" in sub[n]
            ]
            if hr:
                lines.append("|ω̂ − ω| [beats/min], RMS (max) after warm-up: " + ", ".join(hr))
            lines.append("")
        return "\n".join(lines).rstrip()
    lines.append(f"mean RMS one-sample-ahead error [mm], {result['settings']['trials']} trials")
    label = _PARAM_LABEL[study]
    lines.append(f"{label:>10}" + "".join(f"{n:>{w}}" for n in names))
    for p in dict.fromkeys(r["parameter"] for r in rows):
        sub = {r["predictor"]: r for r in rows if r["parameter"] == p}
        head = Path(p).name if study == "rr" else f"{p:g}"
        lines.append(f"{head:>10}" + "".join(f"{sub[n]['rms_mm']:>{w}.3f}" for n in names))
    return "\n".join(lines)


def plot_study(result: dict, path: str | Path) -> Path:
    """Draw the study's curves (one per predictor) to ``path`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    study, rows = result["study"], result["rows"]
    names = list(dict.fromkeys(r["predictor"] for r in rows))
    params = list(dict.fromkeys(r["parameter"] for r in rows))
    if study == "horizon":
        fig, axes = plt.subplots(1, len(params), figsize=(5.5 * len(params), 4), squeeze=False)
        for ax, scn in zip(axes[0], params, strict=True):
            for n in names:
                r = next(r for r in rows if r["parameter"] == scn and r["predictor"] == n)
                ax.plot(r["lead_ms"], r["rms_mm"], marker="o", label=n)
            ax.set(title=scn, xlabel="lead time [ms]", ylabel="RMS error [mm]")
            ax.grid(True, alpha=0.3)
        axes[0][0].legend(fontsize=8)
    else:
        fig, ax = plt.subplots(figsize=(6.5, 4.5))
        x = np.arange(len(params)) if study == "rr" else np.asarray(params, dtype=float)
        for n in names:
            y = [
                next(r for r in rows if r["parameter"] == p and r["predictor"] == n)["rms_mm"]
                for p in params
            ]
            ax.plot(x, y, marker="o", label=n)
        if study == "noise":
            ax.plot(x, x, "k--", lw=1, label="σ_R")
        if study == "rr":
            ax.set_xticks(x, [Path(p).name for p in params])
        ax.set(
            xlabel=_PARAM_LABEL[study],
            ylabel="RMS one-sample-ahead error [mm]",
            title=f"prediction study: {study} (28 Hz, mitral-1d)",
        )
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    path = Path(path)
    io.save_figure(fig, path, dpi=120)
    plt.close(fig)
    return path
