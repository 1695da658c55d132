"""One run's report: the summary a reader sees after ``rhmpc simulate``, and its figure."""

from __future__ import annotations

import numpy as np


def format_summary(doc: dict, settling_rule: str | None = None) -> str:
    """A closed-loop run's document as a few aligned lines (mm, mN·m, µs).

    ``settling_rule``: how the settling time was chosen, stated after it.
    """
    s = doc["settings"]["loop"]
    rule = f", {settling_rule}" if settling_rule else ""
    tick, pred, ctrl = doc["tick_us"], doc["prediction_rms_mm"], doc["controller"]
    fb = ctrl.get("fallbacks", {})
    fails = ctrl.get("failures", {})
    axes = ", ".join(f"{v:.3f}" for v in doc["rms_error_axis_mm"])
    N, Ts = s.get("horizon", 50), s.get("Ts", 0.5e-3)
    lines = [
        f"rhmpc simulate: {doc['predictor']} on {doc['scenario']}, robot {doc['robot']}, "
        f"sensor {doc['sensor']}, seed {doc['seed']}, {s['duration']:g} s "
        f"(metrics after {s['settling']:g} s{rule}; error against the {doc['ground_truth']} "
        "motion)",
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
        + (f", peak memory {doc['peak_rss_mb']:.0f} MB" if "peak_rss_mb" in doc else "")
        + {"compiled": "; control ticks in C between the refresh slices",
           "compiled with the refresh": "; control ticks and refresh slices in C"}.get(
               doc.get("tick_loop"), "")
        + ("; predictor refresh in C" if doc.get("refresh") == "compiled" else ""),
    ]
    counts = doc.get("predictor_counts") or {}
    if counts:  # what the predictor and the safety layers did (missing samples, outliers, …)
        events = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in sorted(counts.items()))
        lines.insert(-1, f"  predictor        {events}")
        lines.insert(-1, "                   " + _clock_line(doc.get("predictor_clock") or {}))
    if doc.get("outlier_gate"):
        lines.insert(-1, "  outlier gate     " + _gate_line(doc["outlier_gate"]))
    if doc.get("host_stalls"):
        lines.append("  host             " + stall_line(doc["host_stalls"]))
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


def _clock_line(clock: dict) -> str:
    """When the predictor ran and how old its newest sample was at a forecast."""
    age = clock.get("mean_sample_age_ms")
    return clock.get("description", "") + (
        f"; newest sample {age:.1f} ms old at a forecast, on average" if age is not None else "")


def _gate_line(gate: dict) -> str:
    """The outlier gate's floor, where it came from, and what it did."""
    floor = gate.get("floor_mm")
    if gate.get("setting") == 0:
        return "off"
    if floor is None:
        where = "still calibrating at the end of the run (all samples accepted)"
    elif gate.get("setting") == "auto":
        where = (f"floor {floor:.3f} mm (4 × the RMS one-step miss of this run's first "
                 "seconds)")
    else:
        where = f"floor {floor:.3f} mm (set)"
    return (f"{where}; rejected {gate.get('outliers_rejected', 0)}, unlocked "
            f"{gate.get('gate_unlocked', 0)}, retracted {gate.get('retracted', 0)} samples")


def stall_line(stalls: dict) -> str:
    """What the host took from a busy loop (:func:`sim.loop.metrics.host_stalls`), in a line."""
    over = stalls.get("over_g")
    longest = f"{stalls['longest_us']:.0f} µs" + (
        f" = {stalls['longest_g']:.0f} g" if "longest_g" in stalls else "")
    return (f"a busy loop of {stalls['seconds']:g} s stalled {stalls['stalls']} times ≥ "
            f"{stalls['floor_us']:g} µs"
            + (f", {stalls[f'over_{over:g}_g']} of them > {over:g} g" if over else "")
            + f"; the longest {longest}, a floor under a tick's maximum on this host")


def _in_gain_ticks(doc: dict) -> str:
    """The tick percentiles as multiples of the gain tick timed in the same run (×g), its
    parts' p99, the tick without the refresh slices, and the wall time per simulated second."""
    r, g = doc["tick_ratio_to_gain"], doc["gain_tick_us"]["p50"]
    parts = ", ".join(f"{name.replace('_', ' ')} {v['p99']:.1f}"
                      for name, v in doc.get("tick_parts_ratio_to_gain", {}).items())
    out = (f"\n                   = {r['p50']:.1f} / {r['p99']:.1f} / {r.get('p999', 0):.1f} / "
           f"{r['max']:.0f} g   (g = gain tick p50 {g:.1f} µs, same run)")
    if parts:
        out += f"\n                   parts p99 [g]: {parts}"
    control = doc.get("control_tick_ratio_to_gain")
    if control:
        out += (f"\n                   without the refresh slices: p99 {control['p99']:.1f} g, "
                f"max {control['max']:.0f} g")
    if "tick_per_simulated_s_g" in doc:
        wall, ticks = doc["wall_per_simulated_s_g"], doc["tick_per_simulated_s_g"]
        out += (f"\n                   per simulated second: wall {wall:.0f} g, of which the "
                f"ticks {ticks:.0f} g")
    return out


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
