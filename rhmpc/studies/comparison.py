"""Tables and figures: the run summary, Tuna-style tracking figures, the comparison table."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def format_summary(doc: dict) -> str:
    """A closed-loop run's document as a few aligned lines (mm, mN·m, µs)."""
    s = doc["settings"]["loop"]
    tick, pred, ctrl = doc["tick_us"], doc["prediction_rms_mm"], doc["controller"]
    fb = ctrl.get("fallbacks", {})
    fails = ctrl.get("failures", {})
    axes = ", ".join(f"{v:.3f}" for v in doc["rms_error_axis_mm"])
    N, Ts = s.get("horizon", 50), s.get("Ts", 0.5e-3)
    lines = [
        f"rhmpc simulate: {doc['predictor']} on {doc['scenario']}, robot {doc['robot']}, "
        f"sensor {doc['sensor']}, seed {doc['seed']}, {s['duration']:g} s "
        f"(metrics after {s['settling']:g} s; error against the {doc['ground_truth']} motion)",
        f"  tracking error   RMS {doc['rms_error_mm']:.3f} mm   max {doc['max_error_mm']:.3f} mm"
        f"   (RMS per axis x, y, z: {axes} mm)",
        f"  control effort   RMS {doc['rms_effort_mNm']:.1f} mN·m (MPC torque; with the "
        f"cancellation {doc['rms_total_torque_mNm']:.1f} mN·m); saturated ticks "
        f"{doc['saturated_ticks']}",
        f"  prediction       horizon RMS error {pred['lead_1']:.3f} mm at {1e3 * Ts:g} ms, "
        f"{pred['lead_N']:.3f} mm at {1e3 * N * Ts:g} ms",
        f"  controller tick  p50 {tick['p50']:.1f} µs   p99 {tick['p99']:.1f} µs   "
        + (f"p99.9 {tick['p999']:.1f} µs   " if "p999" in tick else "")
        + f"max {tick['max']:.1f} µs   (budget {1e6 * Ts:.0f} µs)"
        + (_in_gain_ticks(doc) if "gain_tick_us" in doc else ""),
        f"  QP               {ctrl.get('ticks', 0)} ticks, fallbacks {doc['fallbacks']} "
        f"(plan {fb.get('plan', 0)}, lq {fb.get('lq', 0)}, zero {fb.get('zero', 0)})"
        + (f", failures {fails}" if fails else ""),
        f"  wall time        {doc['wall_s']:.1f} s ({doc['real_time_factor']:.1f}× real time)"
        + (f", peak memory {doc['peak_rss_mb']:.0f} MB" if "peak_rss_mb" in doc else ""),
    ]
    counts = doc.get("predictor_counts") or {}
    if counts:  # what the predictor and the safety layers did (missing samples, outliers, …)
        events = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in sorted(counts.items()))
        lines.insert(-1, f"  predictor        {events}")
    hr = doc.get("heart_rate") or {}
    if hr.get("observations"):  # ω̂ of the EKF/WFLC against the true heart rate
        lock = hr["lock_time_s"]
        lines.insert(-1, f"  heart rate       ω̂ − ω RMS {hr['rms_error_bpm']:.2f} bpm, max "
                     f"{hr['max_error_bpm']:.2f} bpm; within {hr['tolerance_bpm']:g} bpm "
                     f"{100 * hr['within_tolerance']:.1f} % of updates; "
                     + f"estimate from {hr['ready_time_s']:.2f} s, "
                     + (f"locked from {lock:.2f} s" if lock is not None else "unlocked at the end")
                     + f" (true mean {hr['mean_true_bpm']:.1f} bpm)")
    return "\n".join(lines)


def _in_gain_ticks(doc: dict) -> str:
    """The tick percentiles as multiples of the gain tick timed in the same run (×g)."""
    r, g = doc["tick_ratio_to_gain"], doc["gain_tick_us"]["p50"]
    return (f"\n                   = {r['p50']:.1f} / {r['p99']:.1f} / {r.get('p999', 0):.1f} / "
            f"{r['max']:.0f} g   (g = gain tick p50 {g:.1f} µs, same run)")


def plot_run(result, path: str, title: str = "", zoom: tuple[float, float] | None = None) -> None:
    """Tuna et al. Figs 10–11 style: the reference per axis, and the error magnitude.

    Top row: POI position per axis [mm] over the run; bottom: ‖e‖ [mm] over the run superimposed
    on the x-axis reference (right axis), then the same over a zoomed window (default: the
    last 2 s).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = result.time
    poi = 1e3 * (result.poi - np.nanmean(result.poi, axis=0))
    err = 1e3 * np.linalg.norm(result.error, axis=1)
    if zoom is None:
        zoom = (max(t[0], t[-1] - 2.0), t[-1])
    window = (t >= zoom[0]) & (t <= zoom[1])
    settle = result.settings.settling

    fig, axes = plt.subplots(3, 1, figsize=(11, 9), constrained_layout=True)
    ax = axes[0]
    for k, name in enumerate("xyz"):
        ax.plot(t, poi[:, k], lw=0.6, label=f"{name}")
    ax.set(xlabel="time [s]", ylabel="POI position [mm]", title=title or "reference per axis")
    ax.axvspan(t[0], settle, color="0.9", label="settling (not scored)")
    ax.legend(loc="upper right", ncol=4, fontsize=8)
    for ax, mask, label in ((axes[1], slice(None), "whole run"), (axes[2], window, "zoom")):
        ax.plot(t[mask], err[mask], color="C3", lw=0.7, label="‖error‖")
        ax.set(xlabel="time [s]", ylabel="end-effector error [mm]", title=f"error, {label}")
        twin = ax.twinx()
        twin.plot(t[mask], poi[mask, 0], color="0.6", lw=0.6, label="x reference")
        twin.set_ylabel("x reference [mm]", color="0.4")
        ax.set_zorder(twin.get_zorder() + 1)
        ax.patch.set_visible(False)
        ax.legend(loc="upper left", fontsize=8)
        twin.legend(loc="upper right", fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)


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
