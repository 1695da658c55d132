"""One run's report: the summary a reader sees after ``rhmpc simulate``, and its figure
(:func:`plot_run`, from :mod:`rhmpc.report.figures`)."""

from __future__ import annotations

from rhmpc.experiment.faults import REPORTED as FAULT_COUNTS
from rhmpc.report.figures import plot_run as plot_run
from rhmpc.timing.host import stall_line


def _seconds(x: float) -> str:
    """A duration [s] with as many digits as it needs (3 significant, no trailing zeros)."""
    return f"{x:.3g}" if x < 100 else f"{x:.0f}"


def _speed(factor: float) -> str:
    """Simulated over wall time, as a reader says it."""
    if factor >= 1:
        return f"{factor:.3g}× faster than real time"
    return f"{1 / factor:.3g}× slower than real time"


def _placement(loop: dict) -> str:
    """Where the motion was put in the robot's workspace."""
    offset = loop.get("poi_offset", [0, 0, 0])
    shift = "" if not any(offset) else " + poi_offset (" + ", ".join(
        f"{1e3 * v:g}" for v in offset) + ") mm"
    if loop.get("placement", "centred") == "absolute":
        return "the motion's own coordinates as the robot's" + shift + " (placement absolute)"
    return ("the motion centred on its mean, at the tool's home position" + shift
            + " (set loop.placement = \"absolute\" to keep its own coordinates)")


def _budget_line(doc: dict) -> str:
    """Each refresh (gate, predictor, interpolation) against the predictor's period, and a
    combination's slowest member."""
    r = doc["refresh_us"]
    out = (f"each refresh p50 {r['p50']:.0f} µs, p99 {r['p99']:.0f} µs, max {r['max']:.0f} µs "
           f"in a period of {r['period_us'] / 1e3:g} ms: {r['over_period']} of "
           f"{r['refreshes']} longer")
    members = doc.get("member_time_us") or {}
    timed = {k: v for k, v in members.items() if v.get("mean_us") is not None}
    if timed:
        name = max(timed, key=lambda k: timed[k]["mean_us"])
        out += (f"; slowest member {name} {timed[name]['mean_us']:.0f} µs mean, "
                f"{timed[name]['max_us']:.0f} µs max")
    return out


def _score_words(doc: dict) -> str:
    """Where the tracking error was taken: at the measured samples, or at every tick."""
    if doc.get("score") == "measured":
        return f"at the {doc.get('scored_samples', 0)} measured instants"
    return "at every tick"


def _measured_lines(doc: dict) -> str:
    """A recording's second score (every tick against the samples' interpolant) and what the
    score at the measured instants leaves out."""
    ex = doc.get("excluded") or {}
    out = (f"                   every tick against the line between samples (where nobody "
           f"measured): RMS {doc['rms_error_interpolated_mm']:.3f} mm, max "
           f"{doc['max_error_interpolated_mm']:.3f} mm")
    left = [f"{ex[k]} {what}" for k, what in (
        ("outlier_samples", "samples taken as outliers"),
        ("unmeasured_samples", "samples that are no measurements"),
        ("after_last_sample_ticks", "ticks after the last sample")) if ex.get(k)]
    return out + ("\n                   left out: " + ", ".join(left) if left else "")

#: Who served the refreshes (the document's ``implementation``), as the summary names it.
CONTROLLERS = {"python": "the library, the run's predictor in Python",
               "c": "the library with its own RLS predictor"}


def _tick_line(doc: dict, Ts: float) -> str:
    """The controller's tick: the library's step, timed inside C, against the real-time budget,
    with the refreshes (the Python predictor's time included where it served them)."""
    tick = doc["tick_us"]
    times = (f"p50 {tick['p50']:.1f} µs   p99 {tick['p99']:.1f} µs   "
             + (f"p99.9 {tick['p999']:.1f} µs   " if "p999" in tick else "")
             + f"max {tick['max']:.1f} µs")
    line = (f"  controller tick  {times}   (budget {1e6 * Ts:.0f} µs, refreshes included"
            + ("" if doc.get("implementation") == "c" else ", the Python predictor's too") + ")")
    return line + (_in_gain_ticks(doc) if "gain_tick_us" in doc else "")


def format_summary(doc: dict, settling_rule: str | None = None) -> str:
    """A closed-loop run's document as a few aligned lines (mm, mN·m, µs).

    ``settling_rule``: how the settling time was chosen, stated after it.
    """
    s = doc["settings"]["loop"]
    rule = f", {settling_rule}" if settling_rule else ""
    pred, ctrl = doc["prediction_rms_mm"], doc["controller"]
    fb = ctrl.get("fallbacks", {})
    fails = ctrl.get("failures", {})
    axes = ", ".join(f"{v:.3f}" for v in doc["rms_error_axis_mm"])
    N, Ts = doc["settings"].get("mpc", {}).get("horizon", 50), s.get("Ts", 0.5e-3)
    settling = doc.get("settling_s", s.get("settling") or 0.0)
    sources = ", ".join(f"{k} {v}" for k, v in fb.items())
    lines = [
        f"rhmpc simulate: {doc['predictor']} on {doc['scenario']}, robot {doc['robot']}, "
        f"sensor {doc['sensor']}, controller "
        f"{CONTROLLERS.get(doc.get('implementation', 'python'), doc.get('implementation'))}, "
        f"seed {doc['seed']}, {_seconds(s['duration'])} s "
        f"(metrics after {_seconds(settling)} s{rule}; error against the "
        f"{doc['ground_truth']} motion)",
        f"  placement        {_placement(s)}",
        f"  tracking error   RMS {doc['rms_error_mm']:.3f} mm   max {doc['max_error_mm']:.3f} mm"
        f"   (RMS per axis x, y, z: {axes} mm) {_score_words(doc)}",
        f"  control effort   RMS {doc['rms_effort_mNm']:.1f} mN·m (MPC torque; with the "
        f"cancellation {doc['rms_total_torque_mNm']:.1f} mN·m); saturated ticks "
        f"{doc['saturated_ticks']}",
        f"  prediction       horizon RMS error {pred['lead_1']:.3f} mm at {1e3 * Ts:g} ms, "
        f"{pred['lead_N']:.3f} mm at {1e3 * N * Ts:g} ms",
        _tick_line(doc, Ts),
        f"  QP               {ctrl.get('ticks', 0)} ticks, fallbacks {doc['fallbacks']}"
        + (f" ({sources})" if sources else "")
        + (", failures " + ", ".join(f"{k} {v}" for k, v in fails.items()) if fails else ""),
        f"  wall time        {doc['wall_s']:.1f} s ({_speed(doc['real_time_factor'])})"
        + (f", peak memory {doc['peak_rss_mb']:.0f} MB" if "peak_rss_mb" in doc else "")

    ]
    counts = dict(doc.get("predictor_counts") or {})
    if counts:  # what the predictor and the safety layers did (missing samples, outliers, …)
        # a sample the gate rejects is missing for the predictor: "missing" counts the lost ones
        counts["missing"] = counts.get("missing", 0) - counts.get("outliers_rejected", 0)
        events = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in sorted(counts.items()))
        lines.insert(-1, f"  predictor        {events}")
        lines.insert(-1, "                   " + _clock_line(doc.get("predictor_clock") or {}))
    if doc.get("outlier_gate"):
        lines.insert(-1, "  outlier gate     " + _gate_line(doc["outlier_gate"]))
    if doc.get("refresh_us", {}).get("refreshes"):
        lines.insert(-1, "  predictor time   " + _budget_line(doc))
    encoder = doc.get("encoder") or {}
    if encoder.get("held"):  # the observer's innovation gate (rhmpc.control.observer)
        lines.insert(-1, f"  encoders         {encoder['held']} readings held out past the "
                     f"observer's gate, {encoder.get('reacquired', 0)} taken again once they "
                     "moved")
    excluded = doc.get("excluded") or {}
    if doc.get("score") == "measured":
        lines.insert(3, _measured_lines(doc))
    elif excluded.get("ticks") or excluded.get("unmeasured"):
        lines.insert(3, f"                   the score leaves out {excluded.get('ticks', 0)} ticks "
                     f"whose truth touches the {excluded.get('outliers', 0)} samples taken as "
                     f"outliers, and the {excluded.get('unmeasured', 0)} recorded samples that "
                     "are no measurements")
    for line in fault_lines(doc):
        lines.insert(-1, line)
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



def fault_lines(doc: dict) -> list[str]:
    """One line per injected fault (its window, the largest error during it and after it,
    what was counted there, the joint envelope), then the run's joint envelope; none without
    faults, unless the envelope did not hold."""
    lines = []
    for f in doc.get("faults") or []:
        during, after = f.get("during") or {}, f.get("after") or {}
        counts = {k: during.get("counts", {}).get(k, 0) + after.get("counts", {}).get(k, 0)
                  for k in FAULT_COUNTS}
        told = ", ".join(f"{FAULT_COUNTS[k]} {v}" for k, v in counts.items() if v) or "nothing"
        held = during.get("envelope_held", True) and after.get("envelope_held", True)
        error = _mm(during.get("max_error_mm")) + (
            f", {_mm(after.get('max_error_mm'))} in the {_seconds(f['after_s'])} s after"
            if after else " (to the end of the run)")
        lines.append(f"  fault            {f['fault']} ({_seconds(f['start_s'])}–"
                     f"{_seconds(f['end_s'])} s): max error {error}; counted: {told}; joint "
                     f"envelope {'held' if held else 'NOT held'}")
    envelope = doc.get("joint_envelope") or {}
    if envelope and (lines or not envelope.get("held", True)):
        lines.append(f"  joint envelope   {'held' if envelope['held'] else 'NOT held'}: least "
                     f"margin {envelope['position_margin_rad']:.3f} rad to the joint limits, "
                     f"{envelope['speed_margin_rad_s']:.2f} rad/s to the speed limits")
    return lines


def _mm(value: float | None) -> str:
    return "—" if value is None else f"{value:.3f} mm"


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
        learn = gate.get("calibration_s", 10.0)
        where = (f"not armed: it learns its floor over the first {learn:g} s of samples, more "
                 "than this run had (every sample accepted; reference.gate_calibration sets "
                 "half of it)")
    elif gate.get("setting") == "auto":
        where = (f"floor {floor:.3f} mm (4 × the RMS one-step miss of this run's first "
                 "seconds)")
    else:
        where = f"floor {floor:.3f} mm (set)"
    return (f"{where}; rejected {gate.get('outliers_rejected', 0)}, unlocked "
            f"{gate.get('gate_unlocked', 0)}, retracted {gate.get('retracted', 0)} samples")


def _in_gain_ticks(doc: dict) -> str:
    """The tick percentiles as multiples of the gain tick timed in the same run (×g), its
    parts' p99, the tick without the refreshes, and the wall time per simulated second."""
    r, g = doc["tick_ratio_to_gain"], doc["gain_tick_us"]["p50"]
    parts = ", ".join(f"{name.replace('_', ' ')} {v['p99']:.1f}"
                      for name, v in doc.get("tick_parts_ratio_to_gain", {}).items())
    out = (f"\n                   = {r['p50']:.1f} / {r['p99']:.1f} / {r.get('p999', 0):.1f} / "
           f"{r['max']:.0f} g   (g = gain tick p50 {g:.1f} µs, same run)")
    if parts:
        out += f"\n                   parts p99 [g]: {parts}"
    control = doc.get("control_tick_ratio_to_gain")
    if control:
        out += (f"\n                   without the refreshes: p99 {control['p99']:.1f} g, "
                f"max {control['max']:.0f} g")
    if "tick_per_simulated_s_g" in doc:
        wall, ticks = doc["wall_per_simulated_s_g"], doc["tick_per_simulated_s_g"]
        out += (f"\n                   per simulated second: wall {wall:.0f} g, of which the "
                f"ticks {ticks:.0f} g")
    return out
