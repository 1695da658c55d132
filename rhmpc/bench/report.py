"""The text report of ``rhmpc bench`` (:func:`rhmpc.bench.ticks.run_bench`'s result): each
timing's p50 / p99 / max in µs and in gain ticks g, the cascade's levels, the iterations, the
fallbacks and the accuracy against the exact tick."""

from __future__ import annotations

__all__ = ["format_table"]


_ROWS = (
    ("MPC tick (screening cascade, in C)", "tick_us"),
    ("OSQP every tick (Python interface)", "osqp_tick_us"),
    ("  OSQP solve", "solve_us"),
    ("gain tick g (the yardstick)", "gain_tick_us"),
    ("  the same mat-vec in plain NumPy", "numpy_gain_us"),
    ("exact tick, DAQP (reference)", "exact_tick_us"),
)


_LEVELS = {"1": "1 screened", "2": "2 box QP", "3": "3 solver"}


def _level_line(result: dict, counts: str, times: str) -> list[str]:
    out = []
    for v, name in _LEVELS.items():
        n = result[counts][v]
        t = result[times].get(v)
        out.append(f"{name} {n}" + (f" ({t['p50']:.1f} / {t['p99']:.1f} / {t['max']:.1f})"
                                    if t else ""))
    return out


def _iters(row: dict | None) -> str:
    return "none" if row is None else f"p50 {row['p50']:.0f}, p99 {row['p99']:.0f}, max " \
        f"{row['max']:.0f}"


def format_table(result: dict) -> str:
    """Human-readable table of :func:`run_bench` results."""
    lines = [
        f"rhmpc bench: {result['robot']}, {result['ticks']} ticks (+{result['warmup_ticks']} "
        f"warm-up), seed {result['seed']}, nz = {result['nz']}, "
        f"GC {'off' if result['gc_disabled'] else 'on'} during the loop",
        f"{'':36s}{'p50 µs':>9s}{'p99 µs':>9s}{'max µs':>9s}{'p50 ×g':>8s}{'p99 ×g':>8s}",
    ]
    g = result["gain_tick_us"]
    rows = list(_ROWS)
    for label, key in rows:
        row = result[key]
        ratio = ""
        if not label.startswith("  "):
            ratio = f"{row['p50'] / g['p50']:8.2f}{row['p99'] / g['p99']:8.2f}"
        lines.append(f"{label:36s}{row['p50']:9.1f}{row['p99']:9.1f}{row['max']:9.1f}{ratio}")
    it = result["iterations"]
    lines += [
        "(×g = time / gain-tick time of the same run)",
        "screening cascade, ticks per level (MPC tick p50 / p99 / max µs): "
        + "; ".join(_level_line(result, "levels", "level_tick_us")),
        f"  level 2 active-set solves: {_iters(result['box_iterations'])}",
        f"OSQP iterations: p50 {it['p50']:.0f}, p99 {it['p99']:.0f}, max {it['max']:.0f}; "
        f"DAQP iterations p99 {result['exact_iterations']['p99']:.0f}",
        f"fallbacks: {result['fallbacks']}  failures: {result['failures'] or 'none'}  "
        f"(OSQP every tick: {result['osqp_unsolved']} unsolved)",
        f"u0 error vs exact: max {100 * result['u0_error_max_frac']:.4f} % of τ_max, "
        f"p99 {100 * result['u0_error_p99_frac']:.4f} %, levels 1-2 max "
        f"{result['u0_error_cascade_max_frac']:.1e} τ_max (OSQP every tick: max "
        f"{100 * result['osqp_u0_error_max_frac']:.4f} %); ticks with an active bound: "
        f"{result['active_bound_ticks']}",
        f"tracking on the linear model: RMS {result['tracking_rms_mm']:.4f} mm, "
        f"max {result['tracking_max_mm']:.3f} mm (includes the reference jumps)",
    ]
    if "host_stalls" in result:
        from rhmpc.timing.host import stall_line

        lines.append("host: " + stall_line(result["host_stalls"]))
    if "exported_tick_us" in result:
        lines += _exported_lines(result)
    return "\n".join(lines)


def _exported_lines(result: dict) -> list[str]:
    """The exported controller's rows of :func:`format_table`."""
    t, r, g = result["exported_tick_us"], result["exported_tick_g"], \
        result["exported_gain_tick_us"]["p50"]
    refresh = result["exported_refresh_tick_us"]
    lines = [f"exported controller ({result['exported_predictor']} predictor, refresh, "
             "observer, MPC, cancellation), every tick timed inside C:",
             f"  tick p50 {t['p50']:.2f} µs, p99 {t['p99']:.2f} µs, max {t['max']:.1f} µs = "
             f"{r['p50']:.2f} / {r['p99']:.2f} / {r['max']:.1f} g (g = {g:.2f} µs, same run)"]
    if refresh:
        lines.append(f"  refresh ticks: p50 {refresh['p50']:.2f} µs, p99 {refresh['p99']:.2f} "
                     f"µs, max {refresh['max']:.1f} µs")
    bare = result["c_tick_us"]
    lines.append(f"  ticks without a refresh: p50 {bare['p50']:.2f} µs, p99 {bare['p99']:.2f} "
                 "µs")
    lines.append("  ticks per level (p50 / p99 / max µs): " + "; ".join(
        _level_line(result, "exported_levels", "exported_level_tick_us")))
    lines.append(f"  fallbacks {result['exported_fallbacks']}, failures "
                 f"{result['exported_failures'] or 'none'}; tracking on the linear model RMS "
                 f"{result['exported_tracking_rms_mm']:.4f} mm")
    return lines
