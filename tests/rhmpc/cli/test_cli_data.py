"""`rhmpc data list|show|export|plot`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rhmpc.cli import main
from rhmpc.sim.heart.scenarios import available_scenarios
from rhmpc.sim.recordings import load_recording


@pytest.mark.slow
def test_list_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["data", "list", "--json", "--duration", "40"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in rows] == list(available_scenarios())
    assert "arrhythmia-apb" in available_scenarios()  # its record ships with the package
    a2 = rows[0]
    assert a2["target_peak_to_peak_mm"] == 8.39 and a2["target_rms_mm"] == 3.55
    assert a2["rms_mm"] == pytest.approx(3.55, rel=0.03)
    lo, hi = a2["heart_rate_bpm"]  # 100 bpm with heart-rate variability (σ 6 %)
    assert 75 < lo < 100 < hi < 125
    for r in rows:  # 40 s of the replica: nearly the whole record's p-p
        assert 0.93 < r["peak_to_peak_mm"] / r["target_peak_to_peak_mm"] <= 1.0 + 1e-6
        # one-step RLS / hold at 120 ms, 25 Hz: the replicas are regular, the in-vivo regime
        # is as hard as its recording (0.67)
        if r["name"].startswith("invivo"):
            assert 0.55 < r["predictability"] < 0.8
        else:
            assert 0.1 < r["predictability"] < 0.5


@pytest.mark.slow
def test_list_table(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["data", "list", "--duration", "10"]) == 0  # --duration: measured
    out = capsys.readouterr().out
    for name in available_scenarios():
        assert name in out
    assert "p-p" in out and "target" in out and "RLS/hold" in out


def test_list_reads_the_specifications_only(monkeypatch: pytest.MonkeyPatch,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    """Without --measure nothing is synthesised: the list is as fast as the command starts."""
    import rhmpc.motion.figure
    import rhmpc.motion.targets

    def refuse(*args, **kwargs):
        raise AssertionError("data list synthesised a scenario")

    monkeypatch.setattr(rhmpc.motion.targets, "make_scenario", refuse)
    assert main(["data", "list"]) == 0
    out = capsys.readouterr().out
    assert "fixed-a2-top       3    257    472    8.39   3.55  100 + HRV" in out
    assert "staircase 95–152 + HRV" in out and "--measure" in out
    assert max(len(line) for line in out.splitlines()) <= 100
    assert main(["data", "list", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in rows] == list(available_scenarios())
    assert rows[0]["target_peak_to_peak_mm"] == 8.39 and rows[0]["dim"] == 3
    assert "heart_rate" in rows[0]["reported"]


@pytest.mark.slow
def test_show(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["data", "show", "varying-a3-top", "--duration", "60"]) == 0
    out = capsys.readouterr().out
    assert "peak-to-peak" in out and "heart rate" in out and "spectral peaks" in out
    assert "predictability" in out
    assert main(["data", "show", "--json", "--bpm", "72", "--duration", "20"]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["name"] == "fixed-a2-top"
    lo, hi = row["heart_rate_bpm"]  # 72 bpm with heart-rate variability
    assert 55 < lo < 72 < hi < 90
    assert "predictability" in row


@pytest.mark.slow
def test_show_with_record(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                          capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)  # the shipped record by name, outside the repository
    assert main(["data", "show", "fixed-a2-top", "--record", "1003", "--json",
                 "--duration", "60"]) == 0
    row = json.loads(capsys.readouterr().out)
    lo, hi = row["heart_rate_bpm"]
    assert 85 < lo < hi < 110


def test_export_and_show_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "a2.csv"
    assert main(["data", "export", "fixed-a2-top", str(out), "--duration", "5"]) == 0
    assert "wrote 1285 samples" in capsys.readouterr().out
    rec = load_recording(out)
    assert rec.dim == 3 and rec.t.size == 1285
    assert main(["data", "show", str(out), "--json"]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["dim"] == 3 and row["sensor_rate_hz"] == pytest.approx(257.0, rel=1e-3)
    # refuses to overwrite, then does with --force
    assert main(["data", "export", "fixed-a2-top", str(out), "--duration", "5"]) == 2
    assert "exists" in capsys.readouterr().err
    assert main(["data", "export", "mitral-1d", str(out), "--duration", "5", "--force",
                 "--sensor", "ultrasound", "--seed", "3"]) == 0
    noisy = load_recording(out)
    assert noisy.dim == 1 and noisy.t.size == 141


def test_export_npz(tmp_path: Path) -> None:
    out = tmp_path / "v.npz"
    assert main(["data", "export", "varying-a3-side", str(out), "--duration", "3",
                 "--rate", "100"]) == 0
    with np.load(out) as data:
        assert data["position"].shape == (300, 3)
        assert str(data["units"]) == "m"


@pytest.mark.slow
def test_plot(tmp_path: Path) -> None:
    out = tmp_path / "f.png"
    assert main(["data", "plot", "fixed-a2-top", str(out), "--duration", "30"]) == 0
    assert out.stat().st_size > 20_000
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    one = tmp_path / "m.png"
    assert main(["data", "plot", "mitral-1d", str(one), "--window", "4", "--duration", "8"]) == 0
    assert one.is_file()


@pytest.mark.slow
def test_plot_draws_short_records_whole_and_long_ones_with_a_zoom(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A record up to two windows long is one full-resolution line per axis; a longer one has
    the zoomed window beside it; the title's heart rate is the range of the panel's."""
    import rhmpc.motion.figure
    import rhmpc.motion.targets

    seen: dict = {}
    figure = rhmpc.motion.figure.motion_figure

    def spy(plt, target, t, p, rate, heart, stats, args):
        fig = figure(plt, target, t, p, rate, heart, stats, args)
        seen[target.name] = (fig, heart)
        return fig

    monkeypatch.setattr(rhmpc.motion.figure, "motion_figure", spy)
    rec = _heart_csv(tmp_path / "rec.csv", seconds=30.0)
    for name, duration in (("fixed-a2-top", "15"), ("fixed-a2-top", "40"), (str(rec), "30")):
        assert main(["data", "plot", name, str(tmp_path / "f.png"), "--duration", duration]) == 0
        fig, heart = seen[Path(name).name]
        title = fig._suptitle.get_text()
        drawn = [a for a in fig.axes if a.lines]  # x, y, z (their zooms), heart rate, PSD
        assert len(drawn) == (8 if float(duration) > 20 else 5)  # zoom: beyond 2 windows
        lo, hi = np.nanmin(heart.bpm), np.nanmax(heart.bpm)
        summary = f"{lo:.0f} bpm" if hi - lo < 0.5 else f"{lo:.0f}–{hi:.0f} bpm"
        assert f"heart rate {summary}" in title
    assert seen["rec.csv"][1].summary == "72 bpm"  # a 1.2-Hz heart, estimated per 10 s


@pytest.mark.parametrize("argv, message", [
    (["data", "show", "fixed-a9-top"], "unknown scenario 'fixed-a9-top'; valid names"),
    (["data", "show", "missing.csv"], "missing.csv: no such file"),
    (["data", "show", "--duration", "-1"], "--duration must be positive"),
    (["data", "export", "fixed-a2-top", "out.txt"], "must end in .csv or .npz"),
    (["data", "plot", "fixed-a2-top", "f.png", "--window", "0"], "--window must be positive"),
    (["data"], "choose an action"),
])
def test_errors_are_one_line_exit_2(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                    capsys: pytest.CaptureFixture[str], argv: list[str],
                                    message: str) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_malformed_file_is_reported(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("t,x,y,z\n0,1,2,3\n0.1,1,2\n")
    assert main(["data", "show", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "bad.csv, line 3: expected 4 fields" in err


def test_list_without_the_annotations(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    """Where the shipped annotations are missing (a damaged install), arrhythmia-apb is skipped
    with a note, never an error."""
    import rhmpc.sim.heart.specs

    monkeypatch.setattr(rhmpc.sim.heart.specs, "SHARED_DATA", tmp_path)
    assert rhmpc.sim.heart.specs.missing_data("arrhythmia-apb") == \
        tmp_path / "mitdb-100" / "100.atr"
    assert rhmpc.sim.heart.specs.missing_data("fixed-a2-top") is None
    assert "arrhythmia-apb" not in available_scenarios()
    assert main(["data", "list", "--json"]) == 0
    captured = capsys.readouterr()
    assert "arrhythmia-apb" not in captured.out
    assert "# arrhythmia-apb: skipped, needs" in captured.err


def _heart_csv(path: Path, seconds: float = 6.0, rate: float = 25.0, scale: float = 1.0,
               missing_after: int | None = None) -> Path:
    """A CSV of 5 mm of heart-like motion (1.2 Hz heart, 0.25 Hz breathing) [mm × scale]."""
    t = np.arange(0.0, seconds, 1.0 / rate)
    z = scale * np.column_stack([2.5 * np.sin(2 * np.pi * 1.2 * t),
                                 1.5 * np.sin(2 * np.pi * 1.2 * t + 1),
                                 2.0 * np.sin(2 * np.pi * 0.25 * t)])
    if missing_after is not None:
        z[missing_after:] = np.nan
    np.savetxt(path, np.column_stack([t, z]), delimiter=",", header="t,x,y,z", comments="",
               fmt="%.6f")
    return path


def _bad_inputs(d: Path) -> None:
    """Write the bad input files of :data:`BAD_INPUTS` into ``d``."""
    import scipy.io

    (d / "fake.npz").write_bytes(b"PK\x03\x04" + b"\x00" * 200)
    (d / "bigfield.csv").write_text("t,x,y,z\n0," + "1" * 140_000 + ",0,0\n")
    t = np.arange(0.0, 6.0, 1 / 257)
    x = np.column_stack([2 * np.sin(2 * np.pi * 1.6 * t), np.cos(2 * np.pi * 1.6 * t),
                         1.5 * np.sin(2 * np.pi * 0.25 * t)])
    np.savez(d / "complex.npz", t=t, position=(x / 1000).astype(complex) + 1j, units="m")
    with (d / "array.npz").open("wb") as fh:
        np.save(fh, x)
    scipy.io.savemat(d / "fortnight.mat", {"X": x.T, "t": t, "time_units": "fortnight",
                                           "units": "mm"})
    scipy.io.savemat(d / "nounits.mat", {"X": x.T, "t": t})
    scipy.io.savemat(d / "norate.mat", {"X": x.T, "units": "mm"})
    scipy.io.savemat(d / "timed.mat", {"X": x.T, "t": t, "units": "mm"})
    _heart_csv(d / "rec.csv")


#: Bad input: the command, and the first line of stderr (exit code 2).
BAD_INPUTS = [
    (["export", "rec.csv", "out.csv", "--rate", "1e12"],
     "6 s of rec.csv at 1e+12 Hz is 6e+12 samples: export would need about "),
    (["show", "fake.npz"], "fake.npz: not a readable .npz archive (File is not a zip file)"),
    (["show", "bigfield.csv"], "bigfield.csv, line 2: a field longer than 131072 characters"),
    (["export", "fixed-a2-top", "big.csv", "--duration", "1e12"],
     "1e+12 s of fixed-a2-top at 257 Hz is 2.57e+14 samples: export would need about "),
    (["show", "complex.npz"], "complex.npz: 'position' holds complex numbers"),
    (["show", "array.npz"], "array.npz: holds a single .npy array, not an .npz archive"),
    (["show", "fortnight.mat"], "fortnight.mat: time_units 'fortnight' is not a time unit"),
    (["show", "norate.mat"], "norate.mat: the file has no sample times: give the sample rate "
                             "with --rate HZ"),
    (["show", "timed.mat", "--rate", "25"], "timed.mat: --rate 25 Hz disagrees with the time "
                                            "vector 't' in the file (257 Hz)"),
    (["show", "fixed-a2-top", "--bpm", "1e6"], "--bpm must be within 20–250 beats/min, got "
                                               "1e+06"),
    (["show", "fixed-a2-top", "--bpm", "nan"], "--bpm must be within 20–250 beats/min"),
    (["show", "fixed-a2-top", "--duration", "inf"], "--duration must be positive, got inf"),
    (["export", "fixed-a2-top", "out.csv", "--rate", "0"], "--rate must be positive, got 0"),
    (["export", "fixed-a2-top", "no/such/dir/out.csv"], "no/such/dir/out.csv: no such "
                                                        "directory"),
    (["plot", "fixed-a2-top", "f.png", "--window", "nan"], "--window must be positive"),
    (["plot", "fixed-a2-top", "no/such/dir/f.png", "--duration", "5"],
     "no/such/dir/f.png: no such directory"),
]


@pytest.mark.parametrize(("argv", "first_line"), BAD_INPUTS, ids=[" ".join(a)[:40]
                                                                   for a, _ in BAD_INPUTS])
@pytest.mark.slow
def test_bad_input_is_one_line_and_exit_2(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str], argv: list[str],
                                          first_line: str) -> None:
    import rhmpc.motion.figure
    import rhmpc.motion.targets

    monkeypatch.chdir(tmp_path)
    _bad_inputs(tmp_path)
    if argv[0] == "export" and "1e12" in argv:  # refused before any synthesis
        monkeypatch.setattr(rhmpc.motion.targets, "make_scenario", None)
    assert main(["data", *argv]) == 2
    err = capsys.readouterr().err
    assert err.splitlines()[0].startswith(f"rhmpc data: error: {first_line}")
    assert err.count("\n") == 1 and "Traceback" not in err


def test_units_warning_names_the_fix(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _heart_csv(tmp_path / "rec.csv")
    assert main(["data", "show", str(path), "--units", "m", "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["peak_to_peak_mm"] > 4000  # as asked, with a warning
    (line,) = captured.err.splitlines()
    assert line.startswith("rhmpc data: warning: ")
    assert line.endswith("if the file is in millimetres, pass --units mm")
    assert main(["data", "show", str(path), "--json"]) == 0
    assert capsys.readouterr().err == ""


def test_a_recording_almost_all_missing(tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    path = _heart_csv(tmp_path / "gaps.csv", missing_after=5)
    assert main(["data", "show", str(path)]) == 0
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [
        f"rhmpc data: warning: {path}: 96.7 % of the samples are missing (5 of 150 complete, "
        "about 0.2 s of data): what is computed from it rests on those"]
    assert "heart rate        — (not estimable" in captured.out
    assert "missing samples   96.67 %" in captured.out


def test_long_work_is_announced(monkeypatch: pytest.MonkeyPatch,
                                capsys: pytest.CaptureFixture[str]) -> None:
    import rhmpc.motion.figure
    import rhmpc.motion.targets

    monkeypatch.setattr(rhmpc.motion.targets, "ANNOUNCE_AFTER", 0.01)
    assert main(["data", "show", "mitral-1d", "--duration", "5", "--json"]) == 0
    err = capsys.readouterr().err
    assert err.startswith("rhmpc data: show of 5 s of mitral-1d at 28 Hz takes about ")


@pytest.mark.parametrize(("value", "text"), [(9.98667, "9.987"), (472.0, "472"),
                                             (257.069, "257.1"), (0.040, "0.04"),
                                             (29.96, "29.96"), (1e12, "1e+12")])
def test_numbers_are_printed_with_sensible_digits(value: float, text: str) -> None:
    from rhmpc.motion.text import fmt

    assert fmt(value) == text
