"""Recordings users bring: CSV/NPZ loading, validation errors, dropouts, export round trips."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rhmpc.sim.heart import make_scenario
from rhmpc.sim.recordings import (
    RecordedMotion,
    RecordingError,
    RecordingWarning,
    load_recording,
    save_recording,
)
from rhmpc.sim.sources import export_scenario


def _write(tmp_path: Path, text: str, name: str = "rec.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


GOOD = "t,x,y,z\n0.0,1.0,2.0,3.0\n0.5,2.0,3.0,4.0\n1.0,3.0,4.0,5.0\n"


def test_csv_loads_in_seconds_and_millimetres(tmp_path: Path) -> None:
    rec = load_recording(_write(tmp_path, GOOD))
    assert isinstance(rec, RecordedMotion)
    assert rec.dim == 3
    np.testing.assert_allclose(rec.t, [0.0, 0.5, 1.0])
    np.testing.assert_allclose(rec.position(0.25), [1.5e-3, 2.5e-3, 3.5e-3])
    assert rec.position(np.array([0.0, 1.0])).shape == (2, 3)
    assert rec.sample_rate == pytest.approx(2.0)


def test_one_dimensional_csv_and_units(tmp_path: Path) -> None:
    rec = load_recording(_write(tmp_path, "# mitral\nt [s],x [m]\n0,0.001\n0.1,0.002\n"))
    assert rec.dim == 1
    np.testing.assert_allclose(rec.position(0.05), [1.5e-3])
    ms = load_recording(_write(tmp_path, "t_ms,x_um\n0,1000\n100,2000\n", "ms.csv"))
    np.testing.assert_allclose(ms.t, [0.0, 0.1])
    np.testing.assert_allclose(ms.position(0.1), [2e-3])
    with pytest.warns(RecordingWarning, match="spans 980 mm"):  # 1 m: not heart motion
        flag = load_recording(_write(tmp_path, "t,x\n0,1\n1,2\n", "flag.csv"), units="m")
    np.testing.assert_allclose(flag.position(1.0), [2.0])


def test_the_time_column_may_be_named_as_in_a_matlab_file(tmp_path: Path) -> None:
    """``time`` and ``timestamps`` (a MATLAB file's names) read as ``t``, their units too."""
    plain = load_recording(_write(tmp_path, GOOD))
    for header in ("time,x,y,z", "Time,x,y,z", "timestamps,x,y,z", "time [ms],x,y,z"):
        text = GOOD.replace("t,x,y,z", header)
        if "ms" in header:
            text = text.replace("0.5,", "500,").replace("1.0,3", "1000,3")
        rec = load_recording(_write(tmp_path, text, "time.csv"))
        np.testing.assert_array_equal(rec.t, plain.t)
        np.testing.assert_array_equal(rec.position(rec.t), plain.position(plain.t))


def test_dropouts_are_kept_as_missing(tmp_path: Path) -> None:
    text = "t,x,y,z\n0,1,1,1\n1,,,\n2,nan,NaN,nan\n3,4,4,4\n4,5,5,5\n"
    rec = load_recording(_write(tmp_path, text))
    assert rec.t.size == 5  # no row silently dropped
    assert np.isnan(rec.z[1]).all() and np.isnan(rec.z[2]).all()
    p = rec.position(np.array([0.0, 0.5, 1.5, 2.5, 3.0, 3.5]))
    assert np.all(np.isfinite(p[0]))
    assert np.isnan(p[1:4]).all()
    np.testing.assert_allclose(p[4:], [[4e-3] * 3, [4.5e-3] * 3])
    assert np.isnan(rec.position(-1.0)).all() and np.isnan(rec.position(5.5)).all()
    # the last sample holds for its period: 5 samples at 1 Hz last 5 s
    np.testing.assert_allclose(rec.position(4.5), [5e-3] * 3)
    assert rec.duration == 5.0


MALFORMED = {
    "empty file": ("", "empty file"),
    "missing header": ("0,1,2,3\n1,2,3,4\n", "missing header"),
    "bad header names": ("time,a,b,c\n0,1,2,3\n1,2,3,4\n", "not t,x,y,z"),
    "unknown unit": ("t,x_furlong,y_furlong,z_furlong\n0,1,2,3\n1,2,3,4\n", "unknown unit"),
    "mixed units": ("t,x_mm,y_m,z_mm\n0,1,2,3\n1,2,3,4\n", "different units"),
    "wrong field count": ("t,x,y,z\n0,1,2,3\n1,2,3\n", "line 3: expected 4 fields"),
    "not a number": ("t,x,y,z\n0,1,2,3\n1,2,abc,4\n", "line 3: column y: 'abc' is not a number"),
    "time not increasing": ("t,x,y,z\n0,1,2,3\n2,1,2,3\n1,2,3,4\n", "line 4: time 1 is not after"),
    "duplicate time": ("t,x,y,z\n0,1,2,3\n0,1,2,3\n", "line 3: time 0 is not after"),
    "missing time": ("t,x,y,z\n0,1,2,3\n,1,2,3\n", "line 3: time is missing"),
    "infinite value": ("t,x,y,z\n0,1,2,3\n1,inf,2,3\n", "line 3: column x: 'inf' is not finite"),
    "single sample": ("t,x,y,z\n0,1,2,3\n", "at least two samples"),
    "two position axes": ("t,x,y\n0,1,2\n1,2,3\n", "not t,x,y,z or t,x"),
}


@pytest.mark.parametrize("kind", sorted(MALFORMED))
def test_malformed_csv_errors_name_file_line_and_problem(tmp_path: Path, kind: str) -> None:
    text, problem = MALFORMED[kind]
    path = _write(tmp_path, text)
    with pytest.raises(RecordingError) as info:
        load_recording(path)
    message = str(info.value)
    assert str(path) in message
    assert problem in message
    assert "\n" not in message
    assert isinstance(info.value, ValueError)


def test_file_level_errors(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="no such file"):
        load_recording(tmp_path / "absent.csv")
    with pytest.raises(RecordingError, match=r"unsupported file type '\.xlsx'"):
        load_recording(_write(tmp_path, GOOD, "rec.xlsx"))
    with pytest.raises(RecordingError, match="not a readable MATLAB file"):
        load_recording(_write(tmp_path, GOOD, "rec.mat"))
    with pytest.raises(RecordingError, match="a folder, not a regular file"):
        load_recording(tmp_path)
    binary = tmp_path / "bin.csv"
    binary.write_bytes(b"\xff\xfe\x00\x81garbage")
    with pytest.raises(RecordingError, match=r"bin\.csv"):
        load_recording(binary)
    with pytest.raises(RecordingError, match="disagree with the units flag"):
        load_recording(_write(tmp_path, "t,x_mm\n0,1\n1,2\n", "u.csv"), units="m")


def test_npz_errors(tmp_path: Path) -> None:
    t = np.arange(5) / 10
    cases = {
        "keys.npz": (dict(time=t, position=np.zeros((5, 3)), units="mm"), "needs arrays 't'"),
        "shape.npz": (dict(t=t, position=np.zeros((4, 3)), units="mm"), "must have shape"),
        "units.npz": (dict(t=t, position=np.zeros((5, 3))), "no 'units'"),
        "order.npz": (dict(t=t[::-1], position=np.zeros((5, 3)), units="mm"),
                      "times must increase"),
        "inf.npz": (dict(t=t, position=np.full((5, 3), np.inf), units="mm"), "infinite"),
    }
    for name, (arrays, problem) in cases.items():
        path = tmp_path / name
        np.savez(path, **arrays)
        with pytest.raises(RecordingError, match=problem) as info:
            load_recording(path)
        assert name in str(info.value)
    junk = tmp_path / "junk.npz"
    junk.write_text("not a zip")
    with pytest.raises(RecordingError, match=r"junk\.npz"):
        load_recording(junk)


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_export_round_trip(tmp_path: Path, suffix: str) -> None:
    sc = make_scenario("fixed-a2-top", duration=4.0)
    path = export_scenario(sc, tmp_path / f"a2{suffix}")
    rec = load_recording(path)
    assert rec.dim == 3
    assert rec.t.size == int(4.0 * 257)  # 4 s at 257 Hz, the last sample holding its period
    assert rec.sample_rate == pytest.approx(257.0, rel=1e-4)
    np.testing.assert_allclose(rec.z, sc.source.position(rec.t), atol=2e-9)
    t = np.linspace(0.1, 3.9, 500)  # linear interpolation of a 257 Hz record
    np.testing.assert_allclose(rec.position(t), sc.source.position(t), atol=3e-5)


def test_export_by_name_and_1d(tmp_path: Path) -> None:
    path = export_scenario("mitral-1d", tmp_path / "m.csv", duration=2.0, rate=100.0)
    assert path.read_text().splitlines()[1] == "t_s,x_mm"
    rec = load_recording(path)
    assert rec.dim == 1 and rec.t.size == 200 and rec.duration == pytest.approx(2.0)


def test_save_recording_writes_missing_as_empty(tmp_path: Path) -> None:
    z = np.array([[1e-3, 2e-3, 3e-3], [np.nan] * 3, [2e-3, 3e-3, 4e-3]])
    path = save_recording(tmp_path / "d.csv", np.array([0.0, 0.1, 0.2]), z)
    assert path.read_text().splitlines()[2] == "0.100000000,,,"
    back = load_recording(path)
    np.testing.assert_allclose(back.z, z, atol=1e-12)


def test_resampling_at_own_rate_keeps_every_sample(tmp_path: Path) -> None:
    """Times computed as t0 + k/rate hit the file's samples despite rounding (no lost data)."""
    lines = ["t,x"] + [f"{100 + k / 10:.1f},{'' if k == 1 else k}" for k in range(40)]
    rec = load_recording(_write(tmp_path, "\n".join(lines) + "\n"))
    t = 100 + np.arange(40) / 10
    p = rec.position(t)[:, 0]
    assert np.isnan(p[1]) and np.isnan(rec.position(100.05)).all()
    np.testing.assert_allclose(np.delete(p, 1), np.delete(np.arange(40.0), 1) * 1e-3)
    moved = rec.starting_at(0.0)
    np.testing.assert_allclose(moved.t[:3], [0.0, 0.1, 0.2])
    np.testing.assert_allclose(moved.position(0.2), [2e-3])


def test_a_field_beyond_the_csv_limit_is_one_line(tmp_path: Path) -> None:
    path = _write(tmp_path, "t,x,y,z\n0," + "1" * 140_000 + ",0,0\n", "big.csv")
    with pytest.raises(RecordingError, match=r"big\.csv, line 2: a field longer than 131072 "
                       "characters"):
        load_recording(path)


@pytest.mark.parametrize(("name", "content", "problem"), [
    ("fake.npz", b"PK\x03\x04" + b"\x00" * 200, "not a readable .npz archive"),
    ("cut.npz", None, "not a readable .npz archive"),
    ("one.npz", "npy", "holds a single .npy array"),
])
def test_broken_npz_archives(tmp_path: Path, name: str, content, problem: str) -> None:
    path = tmp_path / name
    if content == "npy":
        with path.open("wb") as fh:
            np.save(fh, np.zeros((5, 3)))
    elif content is None:  # a real archive cut short
        np.savez(path, t=np.arange(50.0), position=np.zeros((50, 3)), units="mm")
        path.write_bytes(path.read_bytes()[:300])
    else:
        path.write_bytes(content)
    with pytest.raises(RecordingError, match=problem) as info:
        load_recording(path)
    assert str(info.value).startswith(str(path))


@pytest.mark.parametrize(("arrays", "problem"), [
    (dict(position=np.zeros((5, 3)) + 1j), "'position' holds complex numbers"),
    (dict(position=np.full((5, 3), "a")), "'position' holds <U1 values, not numbers"),
    (dict(position=np.zeros((5, 3)), t=np.arange(5) + 0j), "'t' holds complex numbers"),
])
def test_npz_values_must_be_real_numbers(tmp_path: Path, arrays: dict, problem: str) -> None:
    path = tmp_path / "c.npz"
    np.savez(path, **{"t": np.arange(5) / 10, "units": "m", **arrays})
    with pytest.raises(RecordingError, match=problem):
        load_recording(path)


def test_rate_of_timestamps_written_with_few_decimals(tmp_path: Path) -> None:
    """1/30 s written as 0.033 and 0.034: the rate is 30 Hz, not 1/median = 30.3 Hz."""
    t = np.arange(600) / 30
    lines = ["t,x"] + [f"{ti:.3f},{np.sin(ti):.4f}" for ti in t]
    rec = load_recording(_write(tmp_path, "\n".join(lines) + "\n"))
    assert rec.sample_rate == pytest.approx(30.0, rel=1e-4)
    gappy = RecordedMotion(np.delete(t, [100, 101]), np.zeros((598, 1)))
    assert gappy.sample_rate == pytest.approx(30.0, rel=1e-4)  # a gap counts its samples


def test_units_are_kept_with_the_samples(tmp_path: Path) -> None:
    rec = load_recording(_write(tmp_path, "t,x_um\n0,1000\n1,2000\n"))
    assert (rec.units, rec.units_origin) == ("um", "file")
    assert (rec.starting_at(5.0).units, rec.starting_at(5.0).units_origin) == ("um", "file")
    np.savez(tmp_path / "r.npz", t=np.arange(3.0), position=np.array([[0.0], [0.5], [0.0]]))
    npz = load_recording(tmp_path / "r.npz", units="cm")
    assert (npz.units, npz.units_origin) == ("cm", "option")
