"""The run's figure (rhmpc.report.figures): it draws every run shape, and log axes read."""

from __future__ import annotations

from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest

from rhmpc.report.figures import _plain, plot_run, readable_log_axis
from rhmpc.report.summary import plot_run as report_plot_run
from tests.rhmpc.report.stand_in_run import stand_in_run

matplotlib.use("Agg")


def test_the_report_draws_this_figure() -> None:
    assert report_plot_run is plot_run


@pytest.mark.slow
def test_a_run_with_forecasts_samples_and_limits(tmp_path, phantom) -> None:
    run = stand_in_run(phantom, seconds=3.0)
    out = tmp_path / "run.png"
    plot_run(run, out, title="stand-in", torque_limit=phantom.torque_limit,
             joint_names=["yaw", "shoulder", "elbow"])
    image = matplotlib.image.imread(out)
    assert image.shape[0] > 1000 and image.shape[1] > 1500
    assert np.unique(image.reshape(-1, image.shape[2]), axis=0).shape[0] > 100


@pytest.mark.slow
def test_a_long_decimated_run_without_the_new_fields(tmp_path, phantom) -> None:
    """A trace of every 20th tick plus a full-rate tail, no forecasts, samples or limits."""
    run = stand_in_run(phantom, seconds=60.0, stride=20, settling=10.0)
    bare = SimpleNamespace(**{k: v for k, v in vars(run).items()
                              if k not in ("horizons", "samples", "trace")})
    plot_run(bare, tmp_path / "long.pdf", zoom=(50.0, 53.0))
    assert (tmp_path / "long.pdf").stat().st_size > 10_000


@pytest.mark.parametrize(("lo", "hi", "expected"), [
    (0.05, 0.4, ["0.05", "0.1", "0.2", "0.3", "0.4"]),  # within a decade: every integer
    (0.03, 8.0, ["0.05", "0.1", "0.2", "0.5", "1", "2", "5"]),  # a few: 1, 2, 5
    (1e-3, 200.0, ["0.001", "0.01", "0.1", "1", "10", "100"]),  # many: the decades
])
@pytest.mark.slow
def test_log_axes_have_several_plain_labels(lo: float, hi: float, expected: list[str]) -> None:
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.set_yscale("log")
    ax.set_ylim(lo, hi)
    readable_log_axis(ax)
    fig.canvas.draw()
    labels = [t.get_text() for t in ax.get_yticklabels()
              if lo <= t.get_position()[1] <= hi and t.get_text()]
    plt.close(fig)
    assert [x for x in expected if x in labels] == expected


@pytest.mark.parametrize(("value", "text"), [
    (0.002, "0.002"), (0.5, "0.5"), (1.0, "1"), (20.0, "20"), (1e-6, "1e-6"), (0.0, ""),
])
def test_plain_numbers(value: float, text: str) -> None:
    assert _plain(value) == text


def _svg_texts(path) -> list[str]:
    """The text elements of an SVG written with its text kept as text."""
    import xml.etree.ElementTree as ET

    root = ET.parse(path).getroot()
    return ["".join(e.itertext()) for e in root.iter() if e.tag.endswith("text")]


@pytest.fixture(scope="module")
def short_run():
    from rhmpc.experiment import RunConfig, run_experiment

    config = RunConfig(predictor="one-step").replace(**{"loop.duration": 3.0,
                                                        "loop.settling": 1.0})
    return run_experiment(config)


@pytest.mark.slow
def test_the_paper_figure_is_one_column_vector_and_its_numbers_are_the_summarys(
        tmp_path, short_run) -> None:
    from rhmpc.report.paper_figure import WIDTH_IN, plot_paper
    from rhmpc.report.summary import format_summary

    result, doc = short_run
    pdf, svg = tmp_path / "f.pdf", tmp_path / "f.svg"
    plot_paper(result, doc, pdf)
    plot_paper(result, doc, svg)
    raw = pdf.read_bytes()
    assert raw.startswith(b"%PDF") and b"/Subtype /Image" not in raw  # vector, no raster
    width = float(raw.split(b"/MediaBox [")[1].split(b"]")[0].split()[2])
    assert width == pytest.approx(72 * WIDTH_IN)  # one column [pt]
    texts = _svg_texts(svg)
    assert sum(t.startswith(("(a)", "(b)")) for t in texts) == 2  # two panels
    summary = format_summary(doc)
    rms, peak = f"{doc['rms_error_mm']:.3f}", f"{doc['max_error_mm']:.3f}"
    assert f"RMS {rms} mm   max {peak} mm" in summary
    assert f"RMS {rms} mm (max {peak} mm)" in texts
    assert "forecasts (25 ms)" in texts


@pytest.mark.slow
def test_the_dashboards_title_and_legend_give_the_same_rms(tmp_path, short_run) -> None:
    result, doc = short_run
    svg = tmp_path / "run.svg"
    with matplotlib.rc_context({"svg.fonttype": "none"}):
        plot_run(result, svg, title=f"RMS error {doc['rms_error_mm']:.3f} mm", score=doc)
    texts = _svg_texts(svg)
    assert f"RMS error {doc['rms_error_mm']:.3f} mm" in texts
    assert f"RMS after settling, {doc['rms_error_mm']:.3f} mm" in texts


@pytest.mark.slow
def test_simulate_figure_paper_writes_a_pdf(tmp_path, capsys) -> None:
    from rhmpc.cli import main

    pdf = tmp_path / "f.pdf"
    assert main(["simulate", "--duration", "2", "--plot", str(pdf), "--figure", "paper"]) == 0
    assert pdf.read_bytes().startswith(b"%PDF") and "figure" in capsys.readouterr().out
