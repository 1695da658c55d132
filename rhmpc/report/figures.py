"""Figures of a closed-loop run: what ``rhmpc simulate --plot`` draws.

:func:`plot_run` draws one figure of three columns, readable whatever the run's length: the
whole run, a zoom on a few beats (by default the run's last seconds, which the trace keeps at
full rate) and a detail of a fraction of a second. Its rows: the POI, the tool, the measured
samples and the forecast horizons per axis; the tracking error with the settling span; the
torques against their limits. :func:`readable_log_axis` labels a log axis so that a reader can
use it (1, 2, 5 per decade, in plain numbers); :func:`binned` gives the per-window RMS and peak
that keep a long run's overview readable.

Positions are drawn in millimetres about the POI's mean position, torques in mN·m.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from rhmpc import io

#: Colours shared with the 3-D replay (:mod:`rhmpc.report.replay`).
COLOURS = {"poi": "#d62728", "tool": "#1f77b4", "forecast": "#2ca02c", "samples": "#ff7f0e",
           "settling": "0.88", "zoom": "#fff2cc"}
#: Default zoom: the run's last seconds [s].
ZOOM_S = 2.0
#: Default detail: this many seconds of the zoom [s].
DETAIL_S = 0.25
#: At most this many forecast horizons are drawn in the detail (evenly thinned beyond).
MAX_FORECASTS = 200


def plot_run(result, path: str | Path, title: str = "", zoom: tuple[float, float] | None = None,
             torque_limit: Sequence[float] | None = None,
             joint_names: Sequence[str] | None = None,
             detail: tuple[float, float] | None = None, score: dict | None = None) -> None:
    """Draw a closed-loop run's figure and save it (the format follows ``path``'s suffix).

    Three columns: the whole run, a zoom on a few beats, and a detail of a fraction of a second
    where the forecasts can be read one by one. Rows: x, y and z of the POI, the tool, the
    measured samples and the forecast horizons [mm]; the tracking error ‖tool − POI‖ [mm]; the
    torques against their limits.

    Parameters
    ----------
    result : rhmpc.sim.loop.LoopResult
        The run: its trace (``time``, ``ee``, ``poi``, ``tau``, and ``trace["tau_command"]``
        where present) and ``settings`` (``Ts``, ``settling``); where present, ``horizons`` =
        (ticks (R,), points (R, N, 3)) [m], the reference points of each refresh, and
        ``samples`` = (t (S,), z (S, 3)) [s, m], the measured samples placed in the workspace.
    path : str or pathlib.Path
        The image to write (PNG, PDF, SVG, …).
    title : str
        The figure's title.
    zoom : tuple of float, optional
        The zoomed span [s]; default: the last :data:`ZOOM_S` seconds.
    torque_limit : sequence of float, optional
        Each joint's torque limit [N·m] (``Robot.torque_limit``); without it, the torques are
        drawn without their limits.
    joint_names : sequence of str, optional
        Names for the torque legend; default ``joint 1``, ``joint 2``, ….
    detail : tuple of float, optional
        The detail's span [s]; default: :data:`DETAIL_S` seconds of the zoom around the POI's
        fastest motion.
    score : dict, optional
        The run's document: the RMS error drawn and written is its ``rms_error_mm`` (the
        summary's, scored as the run was); without it, the RMS of ‖tool − POI‖ after settling.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.asarray(result.time, float)
    zoom = zoom or (max(t[0], t[-1] - ZOOM_S), t[-1])
    spans = ((t[0], t[-1]), zoom, detail or _detail_span(result, zoom))
    fig, axes = plt.subplots(5, 3, figsize=(17, 14), sharex="col", constrained_layout=True,
                             gridspec_kw={"width_ratios": (3, 2, 1.4)})
    centre = np.nanmean(np.asarray(result.poi, float), axis=0)
    for k in range(3):
        _position_row(axes[k], result, k, centre, spans)
    _error_row(axes[3], result, spans, None if score is None else score["rms_error_mm"])
    _torque_row(axes[4], result, spans, torque_limit, joint_names)
    _mark_spans(axes[:, 0], result.settings.settling_s, zoom, t[0])
    _mark_spans(axes[:, 1], None, spans[2], t[0])
    for ax, (lo, hi), what in zip(axes[0], spans, ("whole run", "zoom", "detail"), strict=True):
        ax.set_title(f"{what}, {lo:.{_decimals(hi - lo)}f}–{hi:.{_decimals(hi - lo)}f} s")
    for ax, span in zip(axes[-1], spans, strict=True):
        ax.set_xlabel("time [s]")
        ax.set_xlim(*span)
    if title:
        fig.suptitle(title)
    io.save_figure(fig, path, dpi=120)
    plt.close(fig)


def _decimals(width: float) -> int:
    """Decimals that tell a span's ends apart: 1 for seconds, 2 for a few, 3 below 0.5 s."""
    return 1 if width > 10 else 2 if width > 0.5 else 3


def _window(t: np.ndarray, span: tuple[float, float]) -> np.ndarray:
    return (t >= span[0]) & (t <= span[1])


def _detail_span(result, zoom: tuple[float, float]) -> tuple[float, float]:
    """:data:`DETAIL_S` seconds within the zoom, centred where the POI moves fastest."""
    t = np.asarray(result.time, float)
    w = np.flatnonzero(_window(t, zoom))
    if w.size < 3:
        return zoom
    speed = np.linalg.norm(np.gradient(np.asarray(result.poi, float)[w], t[w], axis=0), axis=1)
    half = 0.5 * min(DETAIL_S, zoom[1] - zoom[0])
    mid = float(np.clip(t[w][np.nanargmax(speed)], zoom[0] + half, zoom[1] - half))
    return mid - half, mid + half


def _position_row(row, result, k: int, centre: np.ndarray, spans) -> None:
    """One axis: POI and tool in every column, the samples in the zoom and the detail, the
    forecasts in the detail."""
    t = np.asarray(result.time, float)
    poi = 1e3 * (np.asarray(result.poi, float)[:, k] - centre[k])
    ee = 1e3 * (np.asarray(result.ee, float)[:, k] - centre[k])
    name = "xyz"[k]
    for c, (ax, span) in enumerate(zip(row, spans, strict=True)):
        mask = slice(None) if c == 0 else _window(t, span)
        ax.plot(t[mask], poi[mask], color=COLOURS["poi"], lw=0.9, label="POI (truth)", zorder=3)
        ax.plot(t[mask], ee[mask], color=COLOURS["tool"], lw=0.9, ls="--", label="tool",
                zorder=4)
        ax.set_ylabel(rf"${name} - \bar{{{name}}}_\mathrm{{POI}}$ [mm]")
    _samples(row[1], result, k, centre, spans[1], size=3.5)
    _samples(row[2], result, k, centre, spans[2], size=4.5)
    _forecasts(row[2], result, k, centre, spans[2])
    if k == 0:
        for ax in row:
            ax.legend(loc="upper right", fontsize=8, ncol=2, framealpha=0.9)


def _forecasts(ax, result, k: int, centre: np.ndarray, span: tuple[float, float]) -> None:
    """Each refresh's horizon against the time of its points, as a fan of thin lines."""
    from matplotlib.collections import LineCollection

    horizons = getattr(result, "horizons", None)
    if horizons is None or len(horizons[0]) == 0:
        return
    ticks, points = np.asarray(horizons[0]), np.asarray(horizons[1], float)
    Ts, N = result.settings.Ts, points.shape[1]
    times = (ticks[:, None] + np.arange(1, N + 1)) * Ts  # (R, N) [s]
    chosen = np.flatnonzero((times[:, -1] >= span[0]) & (times[:, 0] <= span[1]))
    every = max(1, -(-chosen.size // MAX_FORECASTS))
    chosen = chosen[::every]
    if chosen.size == 0:
        return
    lines = np.stack([times[chosen], 1e3 * (points[chosen, :, k] - centre[k])], axis=2)
    label = f"forecasts ({N * Ts * 1e3:g} ms)" + (f", 1 in {every}" if every > 1 else "")
    ax.add_collection(LineCollection(lines, colors=COLOURS["forecast"], linewidths=1.0,
                                     alpha=0.8, label=label, zorder=5))


def _samples(ax, result, k: int, centre: np.ndarray, span: tuple[float, float],
             size: float) -> None:
    """The measured samples in ``span``, where and when they were measured, drawn over the
    lines (a dot with a white rim, which reads on the POI's line and the tool's)."""
    samples = getattr(result, "samples", None)
    if samples is None or len(samples[0]) == 0:
        return
    t, z = np.asarray(samples[0], float), np.asarray(samples[1], float)
    w = _window(t, span)
    ax.plot(t[w], 1e3 * (z[w, k] - centre[k]), ls="none", marker="o", ms=size, mew=0.4,
            mec="white", color=COLOURS["samples"], label="measured samples", zorder=6)


def measured_errors(result) -> tuple[np.ndarray, np.ndarray] | None:
    """On a recording, the instants of the samples in the score and ‖tool − sample‖ there
    [s], [mm] (the trace keeps the ticks at those instants); None for a continuous truth."""
    measured = getattr(result, "measured", ())
    if not len(measured):
        return None
    t_k, p, scored = measured
    t, ee = np.asarray(result.time, float), np.asarray(result.ee, float)
    t_k, p = np.asarray(t_k, float)[scored], np.asarray(p, float)[scored]
    tool = np.column_stack([np.interp(t_k, t, ee[:, a]) for a in range(ee.shape[1])])
    return t_k, 1e3 * np.linalg.norm(tool - p, axis=1)


def _error_row(row, result, spans, rms: float | None = None) -> None:
    """‖e‖ over the run on a log axis with the RMS after settling (``rms`` [mm], the run's
    score, or else that of ‖e‖); ‖e‖ in the zoom and detail. On a recording the score's own
    errors, at the measured instants, are drawn over it."""
    t = np.asarray(result.time, float)
    err = 1e3 * np.linalg.norm(np.asarray(result.ee, float) - np.asarray(result.poi, float),
                               axis=1)
    scored = t >= result.settings.settling_s
    if rms is None:
        rms = float(np.sqrt(np.mean(np.square(err[scored])))) if scored.any() else np.nan
    at = measured_errors(result)
    ax = row[0]
    ax.plot(t, np.where(err > 0, err, np.nan), color="0.55", lw=0.5,
            label="‖tool − POI‖" if at is None else "‖tool − line between samples‖")
    centres, rms_per, _, width = binned(t, err)
    ax.plot(centres, rms_per, color="k", lw=1.3, drawstyle="steps-mid",
            label=f"RMS per {width:.3g} s")
    if at is not None:
        ax.plot(*at, ls="none", marker="o", ms=2.5, color=COLOURS["samples"],
                label="‖tool − sample‖ at the measured instants")
    if np.isfinite(rms):
        where = "at the measured instants" if at is not None else "after settling"
        ax.axhline(rms, color=COLOURS["poi"], lw=1.0, ls=":", label=f"RMS {where}, {rms:.3f} mm")
    _log_scale(ax, err)
    ax.set_ylabel("tracking error [mm]")
    for ax, span in zip(row[1:], spans[1:], strict=True):
        w = _window(t, span)
        ax.plot(t[w], err[w], color="0.2", lw=0.9)
        if at is not None:
            m = _window(at[0], span)
            ax.plot(at[0][m], at[1][m], ls="none", marker="o", ms=3, color=COLOURS["samples"])
        ax.set_ylim(bottom=0)
        ax.set_ylabel("tracking error [mm]")


def binned(t: np.ndarray, values: np.ndarray,
           bins: int = 300) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """RMS and peak of ``|values|`` in consecutive windows of ``max(1 s, duration / bins)``
    (a trend that stays readable however long the run).

    Returns
    -------
    centres, rms, peak : numpy.ndarray
        Window centres [s]; RMS and maximum of ``|values|`` per window (NaN where empty), each
        (windows,) for 1-D ``values`` or (windows, columns) for 2-D ones.
    width : float
        The windows' width [s].
    """
    width = max(1.0, (t[-1] - t[0]) / bins)
    edges = np.arange(t[0], t[-1] + width, width)
    n = max(edges.size - 1, 1)
    which = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, n - 1)
    v = np.abs(np.asarray(values, float)).reshape(t.size, -1)
    rms, peak = np.full((n, v.shape[1]), np.nan), np.full((n, v.shape[1]), np.nan)
    for c in range(v.shape[1]):
        ok = np.isfinite(v[:, c])
        count = np.bincount(which[ok], minlength=n)
        total = np.bincount(which[ok], np.square(v[ok, c]), minlength=n)
        top = np.full(n, -np.inf)
        np.maximum.at(top, which[ok], v[ok, c])
        filled = count > 0
        rms[filled, c] = np.sqrt(total[filled] / count[filled])
        peak[filled, c] = top[filled]
    shape = (n,) if np.ndim(values) == 1 else (n, v.shape[1])
    centres = edges[:-1] + 0.5 * width if edges.size > 1 else np.array([t[0]])
    return centres, rms.reshape(shape), peak.reshape(shape), width


def _torque_row(row, result, spans, limit: Sequence[float] | None,
                names: Sequence[str] | None) -> None:
    """The commanded |τ| / τ_max over the run, peak and RMS per window, on a log axis (100 %:
    the limit); the applied τ [mN·m] in the zoom and the detail, with the limits drawn where
    the torque comes within a third of them."""
    t = np.asarray(result.time, float)
    tau = np.asarray(result.tau, float)
    trace = getattr(result, "trace", None) or {}
    command = np.asarray(trace.get("tau_command", tau), float)
    nj = tau.shape[1]
    names = list(names or [f"joint {j + 1}" for j in range(nj)])
    limit = None if limit is None else np.asarray(limit, float)
    for ax, span in zip(row[1:], spans[1:], strict=True):
        w = _window(t, span)
        for j in range(nj):
            ax.plot(t[w], 1e3 * tau[w, j], color=f"C{j}", lw=0.9, label=names[j])
            if limit is not None and np.abs(tau[w, j]).max(initial=0) > limit[j] / 3:
                for sign in (-1, 1):
                    ax.axhline(sign * 1e3 * limit[j], color=f"C{j}", lw=0.8, ls="--")
        ax.set_ylabel("applied torque [mN·m]")
    row[1].legend(loc="upper right", fontsize=8, ncol=3)
    ax = row[0]
    scale = 100 / limit if limit is not None else np.full(nj, 1e3)
    centres, rms, peak, width = binned(t, command * scale)
    for j in range(nj):
        label = names[j] + (f" (limit {1e3 * limit[j]:.0f} mN·m)" if limit is not None else "")
        ax.plot(centres, peak[:, j], color=f"C{j}", lw=1.1, drawstyle="steps-mid", label=label)
        ax.plot(centres, rms[:, j], color=f"C{j}", lw=0.9, ls=":", drawstyle="steps-mid")
    ax.plot([], [], color="0.3", lw=1.1, label=f"peak per {width:.3g} s")
    ax.plot([], [], color="0.3", lw=0.9, ls=":", label=f"RMS per {width:.3g} s")
    if limit is not None:
        ax.axhline(100, color="k", lw=1.0, ls="--", label="limit")
    _log_scale(ax, np.concatenate([peak.ravel(), rms.ravel()]),
               top=150 if limit is not None else None)
    ax.set_ylabel("|commanded torque| / limit [%]" if limit is not None
                  else "|commanded torque| [mN·m]")
    ax.legend(loc="lower right", fontsize=8, ncol=2, framealpha=0.9)


def _log_scale(ax, values: np.ndarray, top: float | None = None, decades: float = 4.0) -> None:
    """A log y axis over the values' bulk: from their 1st percentile (at most ``decades`` below
    the top) to their maximum or ``top``, labelled by :func:`readable_log_axis`."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v) & (v > 0)]
    ax.set_yscale("log")
    if v.size:
        hi = max(top or 0.0, float(v.max())) * 1.3
        lo = max(float(np.percentile(v, 1)), hi * 10.0 ** -decades) / 1.3
        ax.set_ylim(lo, hi)
    readable_log_axis(ax)


def _mark_spans(column, settling: float | None, zoom: tuple[float, float], t0: float) -> None:
    """On each panel of a column: the settling span (not scored), and the span the next column
    shows."""
    for i, ax in enumerate(column):
        if settling is not None:
            ax.axvspan(t0, settling, color=COLOURS["settling"], zorder=0,
                       label="settling (not scored)" if i == 3 else None)
        ax.axvspan(*zoom, color=COLOURS["zoom"], zorder=0,
                   label="span shown on the right" if i == 3 else None)
    column[3].legend(loc="upper right", fontsize=8, framealpha=0.9)


def readable_log_axis(ax, axis: str = "y") -> None:
    """Label a log axis with plain numbers (0.01, 0.02, 0.05, 0.1, …): 1, 2 and 5 per decade
    over up to four decades, every integer multiple within one, decades alone beyond."""
    from matplotlib import ticker

    which = ax.yaxis if axis == "y" else ax.xaxis
    lo, hi = (ax.get_ylim() if axis == "y" else ax.get_xlim())
    decades = np.log10(hi / lo) if lo > 0 and hi > lo else 1.0
    subs = (np.arange(1, 10) if decades <= 1.2 else (1.0, 2.0, 5.0) if decades <= 4
            else (1.0,))
    which.set_major_locator(ticker.LogLocator(base=10, subs=subs, numticks=30))
    which.set_major_formatter(ticker.FuncFormatter(_plain))
    which.set_minor_locator(ticker.LogLocator(base=10, subs=np.arange(2, 10), numticks=30))
    which.set_minor_formatter(ticker.NullFormatter())


def _plain(value: float, _pos=None) -> str:
    """A tick value as a plain number (0.002, 0.5, 1, 20, 1000), in powers of ten beyond."""
    if value <= 0:
        return ""
    exponent = int(np.floor(np.log10(value) + 1e-9))
    if not -4 <= exponent <= 5:
        return f"{value:.0e}".replace("e-0", "e-").replace("e+0", "e")
    return f"{value:.{max(0, -exponent)}f}"
