"""The figures draw what was measured where it was measured, in runs of every length: each
measured sample a run keeps lies on the POI of its own trace at the sample's instant, and the
dashboard and the paper's figure draw it there, over the lines."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest

from rhmpc import io
from rhmpc.experiment import RunConfig, run_experiment
from rhmpc.sim.recordings.shipped import SHIPPED

matplotlib.use("Agg")


def at_instants(result) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, samples, the trace's POI at t) of the kept samples inside the trace [s], [m]."""
    t, z = (np.asarray(a, float) for a in result.samples)
    time, poi = np.asarray(result.time, float), np.asarray(result.poi, float)
    ok = np.isfinite(z).all(axis=1) & (t >= time[0]) & (t <= time[-1])
    truth = np.column_stack([np.interp(t[ok], time, poi[:, a]) for a in range(3)])
    return t[ok], z[ok], truth


@pytest.mark.parametrize("seconds", [3.0, pytest.param(10.0, marks=pytest.mark.slow)])
def test_a_noise_free_sample_lies_on_the_poi_of_its_trace(seconds: float) -> None:
    """A scenario's mean over a short run is not its mean over a long one: the samples are
    placed as the POI is, whatever the run's length (the trace's own numbers, 1 µm: the line
    between two ticks 0.5 ms apart)."""
    config = RunConfig(sensor="ideal").replace(**{"loop.duration": seconds,
                                                  "loop.settling": seconds / 3})
    result, _ = run_experiment(config)
    _, z, truth = at_instants(result)
    assert z.shape[0] > 100
    np.testing.assert_allclose(z, truth, rtol=0, atol=1e-6)


@pytest.mark.slow
def test_a_recording_s_sample_lies_on_its_trace() -> None:
    phantom = SHIPPED["hamlyn-phantom"]
    config = RunConfig(data=str(phantom.path), data_read={**phantom.read, "point": 4},
                       sensor="recorded").replace(**{"loop.duration": 4.0,
                                                     "loop.settling": 1.0})
    result, _ = run_experiment(config)
    _, z, truth = at_instants(result)
    assert z.shape[0] > 50
    np.testing.assert_allclose(z, truth, rtol=0, atol=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("figure", ["dashboard", "paper"])
def test_the_figures_draw_the_samples_where_they_were_measured(figure, monkeypatch) -> None:
    from rhmpc.report.figures import plot_run
    from rhmpc.report.paper_figure import plot_paper

    config = RunConfig(sensor="ideal").replace(**{"loop.duration": 3.0, "loop.settling": 1.0})
    result, doc = run_experiment(config)
    drawn = []
    monkeypatch.setattr(io, "save_figure", lambda fig, *a, **k: drawn.append(fig))
    (plot_run if figure == "dashboard" else plot_paper)(
        *((result, "x.png") if figure == "dashboard" else (result, doc, "x.png")))
    centre = np.nanmean(np.asarray(result.poi, float), axis=0)
    time, poi = np.asarray(result.time, float), np.asarray(result.poi, float)
    found = 0
    for ax in drawn[0].axes:
        for line in ax.get_lines():
            if line.get_label() != "measured samples" or not len(line.get_xdata()):
                continue
            t, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
            k = next(k for k in range(3) if np.allclose(
                y, 1e3 * (np.interp(t, time, poi[:, k]) - centre[k]), atol=1e-3))
            assert line.get_zorder() > max(o.get_zorder() for o in ax.get_lines()
                                           if o is not line)  # over the POI and the tool
            assert line.get_markersize() >= 2.5, k
            found += 1
    assert found >= (6 if figure == "dashboard" else 1)  # zoom and detail, per axis
