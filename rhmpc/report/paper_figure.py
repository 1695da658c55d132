"""A closed-loop run as a figure for a paper: ``rhmpc simulate --plot FILE --figure paper``.

Two panels sized for one column of a two-column journal (:data:`WIDTH_IN`, the IEEE
Transactions' 3.5-inch column): (a) the tracking error ‖tool − POI‖ over the run, the settling
span shaded, with the run's RMS and maximum error as the summary states them; (b) over a
fraction of a second where the POI moves fastest, the POI against the tool along the axis of
its largest motion, with the measured samples and each refresh's forecast horizon. The numbers
written on the figure are the run document's (``rms_error_mm``, ``max_error_mm``, the
settling and the horizon), formatted as the summary prints them. A ``.pdf`` or ``.svg`` file is
vector (text kept as text), a ``.png`` one 300 dpi.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rhmpc import io
from rhmpc.report.figures import (
    COLOURS,
    ZOOM_S,
    _detail_span,
    _forecasts,
    _samples,
    measured_errors,
)

__all__ = ["HEIGHT_IN", "WIDTH_IN", "plot_paper"]

#: The figure's width [in]: one column of the IEEE Transactions' two-column layout.
WIDTH_IN = 3.5
#: The figure's height [in].
HEIGHT_IN = 3.6
#: Font size [pt].
FONT_PT = 8


def plot_paper(result, doc: dict, path: str | Path) -> None:
    """Draw the paper figure of a run and save it (the format follows ``path``'s suffix).

    Parameters
    ----------
    result : rhmpc.sim.loop.LoopResult
        The run's trace (``time``, ``ee``, ``poi``, ``horizons``, ``samples``, ``settings``).
    doc : dict
        The run's document (:func:`rhmpc.experiment.run_experiment`): the numbers written on
        the figure are its ``rms_error_mm``, ``max_error_mm`` and ``settling_s``.
    path : str or pathlib.Path
        The file to write (``.pdf``/``.svg``: vector; ``.png``: 300 dpi).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    style = {"font.size": FONT_PT, "axes.titlesize": FONT_PT, "axes.labelsize": FONT_PT,
             "legend.fontsize": FONT_PT - 1, "xtick.labelsize": FONT_PT - 1,
             "ytick.labelsize": FONT_PT - 1, "svg.fonttype": "none", "pdf.fonttype": 42}
    with plt.rc_context(style):
        fig, (top, bottom) = plt.subplots(2, 1, figsize=(WIDTH_IN, HEIGHT_IN),
                                          constrained_layout=True)
        _error_panel(top, result, doc)
        _tracking_panel(bottom, result)
        io.save_figure(fig, path, dpi=300)
        plt.close(fig)


def _error_panel(ax, result, doc: dict) -> None:
    """(a) ‖tool − POI‖ [mm] over the run, settling shaded, the document's RMS and maximum; on
    a recording, ‖tool − sample‖ at the measured instants, where the run is scored."""
    t = np.asarray(result.time, float)
    settling = float(doc.get("settling_s", result.settings.settling_s))
    ax.axvspan(t[0], settling, color=COLOURS["settling"], lw=0, label="settling")
    at = measured_errors(result)
    if at is None:
        err = 1e3 * np.linalg.norm(np.asarray(result.ee, float) - np.asarray(result.poi, float),
                                   axis=1)
        ax.plot(t, err, color="0.3", lw=0.5, label="‖tool − POI‖")
    else:
        ax.plot(*at, color="0.3", lw=0.5, marker="o", ms=1.5,
                label="‖tool − sample‖ at the measured instants")
    rms, peak = doc["rms_error_mm"], doc["max_error_mm"]
    ax.axhline(rms, color=COLOURS["poi"], lw=1.0, ls="--",
               label=f"RMS {rms:.3f} mm (max {peak:.3f} mm)")
    ax.set(xlim=(t[0], t[-1]), ylim=(0, None), xlabel="time [s]", ylabel="error [mm]")
    ax.set_title("(a) tracking error", loc="left")
    ax.legend(loc="upper right", frameon=False, ncol=1)


def _tracking_panel(ax, result) -> None:
    """(b) POI, tool, samples and forecasts along the POI's axis of largest motion."""
    t = np.asarray(result.time, float)
    poi = np.asarray(result.poi, float)
    k = int(np.nanargmax(np.nanmax(poi, axis=0) - np.nanmin(poi, axis=0)))
    zoom = (max(t[0], t[-1] - ZOOM_S), t[-1])
    span = _detail_span(result, zoom)
    w = (t >= span[0]) & (t <= span[1])
    centre = np.nanmean(poi, axis=0)
    label = "POI" if measured_errors(result) is None else "POI, a line between samples"
    ax.plot(t[w], 1e3 * (poi[w, k] - centre[k]), color=COLOURS["poi"], lw=1.0, label=label)
    ax.plot(t[w], 1e3 * (np.asarray(result.ee, float)[w, k] - centre[k]),
            color=COLOURS["tool"], lw=1.0, ls="--", label="tool")
    _samples(ax, result, k, centre, span, size=2.5)
    _forecasts(ax, result, k, centre, span)
    name = "xyz"[k]
    ax.set(xlim=span, xlabel="time [s]", ylabel=f"{name} about the POI's mean [mm]")
    ax.set_title(f"(b) POI and tool along {name}, with forecasts", loc="left")
    ax.legend(loc="best", frameon=False, ncol=2)
