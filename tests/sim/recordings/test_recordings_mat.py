"""MATLAB recordings (rhmpc.sim.recordings.matfile): v5 and v7.3, orientation, rows/cols, time,
units, refusals."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from rhmpc.sim.recordings import RecordingError, RecordingWarning, load_mat, load_recording

T = np.arange(0, 2, 0.01)
XYZ = np.vstack([4 * np.sin(2 * np.pi * 1.3 * T), 2 * np.sin(2 * np.pi * 2.6 * T),
                 3 * np.cos(2 * np.pi * 1.3 * T)])  # mm, coordinates × samples


def _v5(tmp_path: Path, name: str = "rec.mat", **variables) -> Path:
    path = tmp_path / name
    scipy.io.savemat(path, variables)
    return path


def _v73(tmp_path: Path, **variables) -> Path:
    """A MATLAB v7.3 file: HDF5 with MATLAB's 512-byte header block; arrays stored
    transposed (column-major), strings as uint16 with MATLAB_class 'char'."""
    import h5py

    path = tmp_path / "rec73.mat"
    with h5py.File(path, "w", userblock_size=512) as f:
        for key, value in variables.items():
            if isinstance(value, str):
                d = f.create_dataset(key, data=np.array([[ord(c)] for c in value], np.uint16))
                d.attrs["MATLAB_class"] = np.bytes_("char")
            else:
                d = f.create_dataset(key, data=np.asarray(value, float).T)
                d.attrs["MATLAB_class"] = np.bytes_("double")
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 .".ljust(116)
    header += b" " * 8 + b"\x00\x02" + b"IM"
    with path.open("r+b") as fh:
        fh.write(header.ljust(512, b"\x00"))
    return path


def test_v5_rows_with_rate(tmp_path: Path) -> None:
    rec = load_recording(_v5(tmp_path, X=XYZ), var="X", rate=100.0, units="mm")
    assert rec.dim == 3 and rec.t.size == T.size
    np.testing.assert_allclose(rec.t, T, atol=1e-12)
    np.testing.assert_allclose(rec.z, XYZ.T * 1e-3)
    assert rec.sample_rate == pytest.approx(100.0)
    assert (rec.units, rec.units_origin) == ("mm", "option")


def test_v5_samples_along_rows_with_time_vector_and_units(tmp_path: Path) -> None:
    path = _v5(tmp_path, P=XYZ.T * 1e-3, t=(T + 5.0)[:, None], units="m")
    rec = load_recording(path)  # the only matrix besides t: no --var needed
    np.testing.assert_allclose(rec.t, T + 5.0)
    np.testing.assert_allclose(rec.z, XYZ.T * 1e-3)
    with pytest.raises(RecordingError, match="disagree"):
        load_recording(path, units="mm")


def test_rows_and_cols_pick_coordinates(tmp_path: Path) -> None:
    wide = np.vstack([np.zeros(T.size), XYZ, np.ones(T.size)])  # 5 series × samples
    rec = load_recording(_v5(tmp_path, D=wide), var="D", rows=[1, 2, 3], rate=100.0,
                         units="mm")
    np.testing.assert_allclose(rec.z, XYZ.T * 1e-3)
    rec = load_recording(_v5(tmp_path, "c.mat", D=wide.T), var="D", cols=[3, 2, 1],
                         rate=100.0, units="mm")
    np.testing.assert_allclose(rec.z, XYZ[::-1].T * 1e-3)
    one = load_recording(_v5(tmp_path, "one.mat", D=wide), var="D", rows=[2], rate=100.0,
                         units="mm")
    assert one.dim == 1


def test_v73(tmp_path: Path) -> None:
    path = _v73(tmp_path, X=XYZ, units="mm")
    rec = load_recording(path, var="X", rate=100.0)
    np.testing.assert_allclose(rec.z, XYZ.T * 1e-3)
    assert load_recording(_v73(tmp_path, X=XYZ.T, time=T), var="X", units="mm").duration == \
        pytest.approx(T[-1] + (T[1] - T[0]))  # the last sample holds its period


@pytest.mark.parametrize(("variables", "kwargs", "message"), [
    (dict(Y=XYZ), dict(var="X", rate=100.0), "no numeric variable 'X'"),
    (dict(X=np.zeros((3, 3))), dict(var="X", rate=100.0), "ambiguous"),
    (dict(X=np.zeros((4, 5))), dict(var="X", rate=100.0), "ambiguous"),
    (dict(X=XYZ), dict(var="X", rows=[0, 1, 7], rate=100.0), "cannot take rows"),
    (dict(X=np.zeros((3, 1))), dict(var="X", rows=[0, 1, 2], rate=100.0), "1 sample"),
    (dict(X=XYZ, t=np.r_[T[:50], T[48:198]]), dict(var="X"), "does not increase"),
    (dict(X=XYZ, t=T[:10]), dict(var="X"), "has 10 samples"),
    (dict(X=XYZ), dict(var="X"), "no sample times: give the sample rate with --rate HZ"),
    (dict(X=XYZ + 1j, units="mm"), dict(var="X", rate=100.0), "'X' holds complex numbers"),
    (dict(X=XYZ, t=T, time_units="fortnight"), dict(var="X", units="mm"),
     "time_units 'fortnight' is not a time unit"),
    (dict(X=XYZ, t=T, units="mm"), dict(var="X", rate=25.0),
     r"--rate 25 Hz disagrees with the time vector 't' in the file \(100 Hz\)"),
    (dict(X=XYZ, fs=100.0, units="mm"), dict(var="X", rate=25.0),
     "disagrees with the rate 'fs'"),
    (dict(X=XYZ, fs=-1.0, units="mm"), dict(var="X"), "'fs' in the file must be positive"),
    (dict(X=np.full((3, 50), np.nan)), dict(var="X", rate=100.0), "all NaN"),
    (dict(X=XYZ, Z=XYZ), dict(rate=100.0), "--var"),
])
def test_refusals(tmp_path: Path, variables: dict, kwargs: dict, message: str) -> None:
    with pytest.raises(RecordingError, match=message):
        load_recording(_v5(tmp_path, **variables), **kwargs)


def test_not_a_mat_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.mat"
    bad.write_text("hello")
    with pytest.raises(RecordingError, match="not a readable MATLAB"):
        load_recording(bad, var="X", rate=10.0)


def test_all_nan_csv_refused(tmp_path: Path) -> None:
    path = tmp_path / "nan.csv"
    path.write_text("t,x,y,z\n0,,,\n0.01,nan,nan,nan\n0.02,,,\n")
    with pytest.raises(RecordingError, match="no complete sample"):
        load_recording(path)


def test_time_units_in_microseconds_are_converted(tmp_path: Path) -> None:
    rec = load_recording(_v5(tmp_path, X=XYZ, t=T * 1e6, time_units="us", units="mm"), var="X")
    np.testing.assert_allclose(rec.t, T)
    assert rec.sample_rate == pytest.approx(100.0)


def test_the_rate_from_the_file_and_an_agreeing_option(tmp_path: Path) -> None:
    path = _v5(tmp_path, X=XYZ, Fs=100.0, units="mm")
    assert load_recording(path, var="X").sample_rate == pytest.approx(100.0)
    assert load_recording(path, var="X", rate=100.2).sample_rate == pytest.approx(100.0)
    timed = _v5(tmp_path, "timed.mat", X=XYZ, t=T, units="mm")
    np.testing.assert_allclose(load_recording(timed, var="X", rate=100.0).t, T)


def test_a_file_that_states_no_unit_is_read_in_millimetres(tmp_path) -> None:
    """No ``units`` in the file nor given: millimetres, the format's default as for CSV, and
    said so; motion implausible in millimetres warns with the likely unit."""
    path = tmp_path / "rec.mat"
    scipy.io.savemat(path, {"X": XYZ})
    rec = load_recording(path, var="X", rate=100.0)
    assert (rec.units, rec.units_origin) == ("mm", "default")
    np.testing.assert_allclose(rec.z, 1e-3 * XYZ.T)
    scipy.io.savemat(path, {"X": 1e3 * XYZ})  # micrometres read as millimetres
    with pytest.warns(RecordingWarning, match="--units um"):
        load_recording(path, var="X", rate=100.0)


def test_only_the_variables_a_recording_needs_are_read(tmp_path: Path) -> None:
    """A huge variable beside the recording is never loaded, in v5 and v7.3 (h5py: a dataset
    declared 10¹² values and never written)."""
    import h5py

    path = _v73(tmp_path, X=np.ones((3, 50)), fs=np.array([[25.0]]), units="mm")
    with h5py.File(path, "a") as f:
        f.create_dataset("other", shape=(10**6, 10**6), dtype="f8", chunks=(100, 100))
        f["other"].attrs["MATLAB_class"] = np.bytes_("double")
    rec = load_mat(path, var="X")
    assert rec.t.size == 50 and rec.sample_rate == pytest.approx(25.0)


def test_a_variable_of_more_samples_than_fit_is_refused_before_it_is_read(tmp_path: Path,
                                                                          monkeypatch) -> None:
    from rhmpc import io
    from rhmpc.io.limits import Bound

    monkeypatch.setitem(io.BOUNDS, "samples", Bound("samples of a recording", 1e9, 0.0))
    path = tmp_path / "r.mat"
    scipy.io.savemat(path, {"X": np.ones((3, 100)), "fs": 25.0, "units": "mm"})
    with pytest.raises(ValueError, match=r"r\.mat: 'X': 100 samples of a recording would take "
                                         r"about 100 GB of memory; at most 2 fit"):
        load_mat(path)
    csv_path = tmp_path / "r.csv"
    csv_path.write_text("t,x\n" + "".join(f"{k / 25},1\n" for k in range(10)))
    with pytest.raises(ValueError, match=r"r\.csv: 11 samples of a recording would take"):
        load_recording(csv_path)
