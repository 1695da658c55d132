"""Files of several tracked points: CSV t,x1,y1,z1,…, NPZ (n, P, 3) or (n, 3P), MAT 3P × n."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from rhmpc.sim.recordings import RecordingError, load_points, load_recording

T = np.arange(0.0, 4.0, 0.04)
#: four points, (n, 4, 3) [mm]
P = np.stack([np.stack([np.sin(T + k), np.cos(T + k), 0.1 * k * T], 1) for k in range(4)], 1)


def _csv(path: Path, points: int) -> Path:
    head = ",".join(["t_s", *(f"{a}{k}_mm" for k in range(1, points + 1) for a in "xyz")])
    body = np.column_stack([T, P[:, :points].reshape(T.size, -1)])
    np.savetxt(path, body, delimiter=",", header=head, comments="")
    return path


@pytest.mark.parametrize("kind", ["csv", "npz-3d", "npz-wide", "mat-rows", "mat-cols"])
def test_every_format_gives_the_points_in_order(tmp_path: Path, kind: str) -> None:
    read: dict = {}
    if kind == "csv":
        path = _csv(tmp_path / "p.csv", 4)
    elif kind.startswith("npz"):
        path = tmp_path / "p.npz"
        pos = P * 1e-3 if kind == "npz-3d" else (P * 1e-3).reshape(T.size, -1)
        np.savez(path, t=T, position=pos, units="m")
    else:
        path = tmp_path / "p.mat"
        wide = P.reshape(T.size, -1)
        scipy.io.savemat(path, {"X": wide.T if kind == "mat-rows" else wide})
        read = {"rate": 25.0, "units": "mm"}
    points = load_points(path, **read)
    assert len(points) == 4
    for k, rec in enumerate(points):
        assert rec.dim == 3 and rec.name == f"{path}:p{k + 1}"
        np.testing.assert_allclose(rec.z, P[:, k] * 1e-3, atol=1e-12)
        np.testing.assert_allclose(rec.t, T, atol=1e-12)
    one = load_recording(path, point=3, **read)
    np.testing.assert_allclose(one.z, P[:, 2] * 1e-3, atol=1e-12)
    with pytest.raises(RecordingError, match="tracked points"):
        load_recording(path, **read)  # which point: the caller must say
    with pytest.raises(RecordingError, match=r"no point 5; the file holds 4 \(point = 1…4\)"):
        load_recording(path, point=5, **read)


def test_one_point_files_are_files_of_one_point(tmp_path: Path) -> None:
    path = _csv(tmp_path / "one.csv", 1)  # t,x1,y1,z1 reads like t,x,y,z
    (rec,) = load_points(path)
    np.testing.assert_allclose(load_recording(path).z, rec.z)
    assert rec.name == str(path) and load_recording(path, point=1).dim == 3


def test_mat_rows_still_pick_one_point(tmp_path: Path) -> None:
    path = tmp_path / "p.mat"
    scipy.io.savemat(path, {"X": P.reshape(T.size, -1).T})
    rec = load_recording(path, rate=25.0, rows=[3, 4, 5], units="mm")
    np.testing.assert_allclose(rec.z, P[:, 1] * 1e-3, atol=1e-12)


def test_a_point_without_data_is_named(tmp_path: Path) -> None:
    path = tmp_path / "p.npz"
    pos = P.copy()
    pos[:, 2] = np.nan
    np.savez(path, t=T, position=pos, units="mm")
    with pytest.raises(RecordingError, match="point 3 has no complete sample"):
        load_points(path)


def test_bad_point_columns(tmp_path: Path) -> None:
    path = tmp_path / "p.csv"
    path.write_text("t,x1,y1,z1,x3,y3,z3\n0,1,2,3,4,5,6\n1,1,2,3,4,5,6\n")
    with pytest.raises(RecordingError, match="are not t,x,y,z"):
        load_points(path)
    np.savez(tmp_path / "q.npz", t=T, position=np.zeros((T.size, 5)), units="m")
    with pytest.raises(RecordingError, match="for P tracked points"):
        load_points(tmp_path / "q.npz")
