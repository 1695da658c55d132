"""The open-loop study's report (:func:`rhmpc.openloop.recordings.run_open_loop`): the text
tables of ``rhmpc predict --data`` and the figure of ``--plot``."""

from __future__ import annotations

from rhmpc import io
from rhmpc.openloop.plan import WARMUP_FRACTION, WARMUP_SECONDS

__all__ = ["format_report", "plot_leads"]


def _lead_head(rows: list[dict], leads: list[int]) -> str:
    period = {r["lead_samples"]: r["lead_s"] for r in rows}
    k_loop = next((r["lead_samples"] for r in rows if r["loop_lead"]), None)
    return "".join(f"{f'{k}/{1e3 * period[k]:.0f}' + ('*' if k == k_loop else ''):>10}"
                   for k in leads)


def _table(rows: list[dict], names: list[str], key: str, extra: bool) -> list[str]:
    """One line per predictor: ``key`` per lead (and the ratios and events if ``extra``)."""
    leads = sorted({r["lead_samples"] for r in rows})
    k_loop = next((r["lead_samples"] for r in rows if r["loop_lead"]), leads[-1])
    by = {(r["predictor"], r["lead_samples"]): r for r in rows}
    head = f"{'predictor':<12}{'family':<12}" + _lead_head(rows, leads)
    if extra:
        head += f"{'÷hold 1':>9}{'÷hold *':>9}{'rejected':>10}{'repaired':>10}"
    lines = [head]
    for name in names:
        if (name, leads[0]) not in by:
            continue
        cells = [by[name, k][key] for k in leads]
        line = f"{name:<12}{by[name, leads[0]]['family']:<12}" + "".join(
            f"{'—':>10}" if v is None else f"{v:>10.3f}" for v in cells)
        if extra:
            ratios = [by[name, k]["ratio_to_hold"] for k in (leads[0], k_loop)]
            line += "".join(f"{'—':>9}" if v is None else f"{v:>9.2f}" for v in ratios)
            line += f"{by[name, k_loop]['rejected']:>10}{by[name, k_loop]['repaired']:>10}"
        lines.append(line)
    return lines


def _source_line(s: dict, doc: dict) -> str:
    period_ms = 1e3 * s["period_s"]
    gaps = f", {s['gap_samples']} missing between timestamps" if s["gap_samples"] else ""
    if doc.get("protocol") == "split":
        scored = (f"forecasts issued at frames {s['scored_from']}–{s['scored_to'] - 1} scored, "
                  f"the fitted predictors fitted on {doc['fitted_on']}")
    else:
        rule = ("given" if doc["warmup_rule"] == "given" else "the longer of "
                f"{WARMUP_SECONDS:g} s and {100 * WARMUP_FRACTION:g} % of the recording")
        scored = f"warm-up {s['warmup_s']:.1f} s excluded ({rule})"
    return (f"{s['label']}: {s['samples']} samples at {s['rate_hz']:.4g} Hz (Δ {period_ms:.3g} "
            f"ms), {s['duration_s']:.1f} s, {s['missing']} missing{gaps}; {scored}; "
            "the closed loop needs lead "
            f"{s['loop_lead_samples']} = {1e3 * s['loop_lead_s']:.0f} ms "
            f"(⌈(Δ + λ + N·Ts)/Δ⌉ = ⌈({period_ms:.3g} + {1e3 * doc['latency_s']:g} + "
            f"{1e3 * doc['horizon_s']:g})/{period_ms:.3g}⌉)")


def format_report(doc: dict) -> str:
    """The open-loop tables of :func:`run_open_loop`: per source, RMS and max error by lead."""
    names = doc["predictors"]
    described = {s["label"]: s for s in doc["sources"]}
    out = []
    for label in dict.fromkeys(r["source"] for r in doc["results"]):
        rows = [r for r in doc["results"] if r["source"] == label]
        if label in described:
            out.append(_source_line(described[label], doc))
        else:
            out.append(f"{label}: the mean over {rows[0]['points']} points")
        when = "scored" if doc.get("protocol") == "split" else "after the warm-up"
        out.append("RMS forecast error [mm] at lead [samples/ms] (* the closed loop's lead); "
                   f"÷hold: RMS over hold's; events {when}")
        out += _table(rows, names, "rms_error_mm", True)
        out.append("max forecast error [mm]")
        out += _table(rows, names, "max_error_mm", False)
        out.append("")
    return "\n".join(out).rstrip()


def plot_leads(doc: dict, path) -> None:
    """RMS error against lead [ms], every predictor, one panel per source (PNG at ``path``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = list(dict.fromkeys(r["source"] for r in doc["results"]))
    fig, axes = plt.subplots(len(labels), 1, figsize=(8, 3.6 * len(labels)), squeeze=False)
    for ax, label in zip(axes[:, 0], labels, strict=True):
        rows = [r for r in doc["results"] if r["source"] == label]
        styles = {"baseline": ("--", 1.0), "adaptive": ("-", 1.0), "multi-point": ("-.", 1.5),
                  "learned": (":", 1.8), "combination": ("-", 2.6)}
        for i, name in enumerate(doc["predictors"]):
            mine = [r for r in rows if r["predictor"] == name and r["rms_error_mm"] is not None]
            pts = sorted((1e3 * r["lead_s"], r["rms_error_mm"]) for r in mine)
            if pts:
                x, y = zip(*pts, strict=True)
                style, width = styles.get(mine[0].get("family"), ("-", 1.0))
                ax.plot(x, y, style, lw=width, marker="o", ms=3, color=f"C{i % 10}",
                        label=f"{name} ({mine[0].get('family')})")
        loop = [1e3 * r["lead_s"] for r in rows if r["loop_lead"]]
        if loop:
            ax.axvline(loop[0], color="0.5", lw=0.8, ls=":", label="closed loop's lead")
        ax.set(xlabel="lead [ms]", ylabel="RMS forecast error [mm]", title=label)
        ax.set_yscale("log")
        ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    io.save_figure(fig, path, dpi=110)
    plt.close(fig)
