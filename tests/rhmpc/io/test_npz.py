"""NPZ archives member by member: a header is checked before its data; nothing unpickled."""

from __future__ import annotations

import zipfile
from io import BytesIO
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rhmpc import io


def _archive(tmp_path: Path, **arrays) -> Path:
    path = tmp_path / "a.npz"
    np.savez(path, **arrays)
    return path


def test_members_are_read_after_their_headers(tmp_path: Path) -> None:
    path = _archive(tmp_path, t=np.arange(5.0), label=np.array("mm"),
                    f=np.asfortranarray(np.arange(6.0).reshape(2, 3)))
    with io.NpzArchive(path) as npz:
        assert npz.names == ["t", "label", "f"]
        assert npz.header("t") == ((5,), np.dtype(float))
        np.testing.assert_array_equal(npz.read("t"), np.arange(5.0))
        assert str(npz.read("label")) == "mm"
        np.testing.assert_array_equal(npz.read("f"), np.arange(6.0).reshape(2, 3))
        with pytest.raises(io.FileError, match=r"array 't' of shape \(5,\) would take "
                                                     r"40 B; at most 8 B are read"):
            npz.read("t", max_bytes=8)


def test_objects_are_never_unpickled(tmp_path: Path) -> None:
    path = _archive(tmp_path, o=np.array([1, "x"], dtype=object))
    with io.NpzArchive(path) as npz, pytest.raises(io.FileError,
                                                         match="holds object values"):
        npz.read("o")


def test_a_header_that_lies_about_the_size_is_refused(tmp_path: Path) -> None:
    small = BytesIO()
    np.lib.format.write_array(small, np.zeros(2))
    forged = small.getvalue().replace(b"(2,)", b"(9999999999,)".ljust(4))
    path = tmp_path / "forged.npz"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("t.npy", forged)
    with io.NpzArchive(path) as npz, pytest.raises(io.FileError):
        npz.read("t")


@settings(max_examples=60, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cut=st.integers(0, 400), flip=st.integers(0, 400), byte=st.integers(0, 255))
def test_a_damaged_archive_is_one_line_naming_it(tmp_path: Path, cut: int, flip: int,
                                                 byte: int) -> None:
    data = bytearray(_archive(tmp_path, t=np.arange(20.0), z=np.ones((20, 3))).read_bytes())
    if flip < len(data):
        data[flip] = byte
    path = tmp_path / "damaged.npz"
    path.write_bytes(bytes(data[: len(data) - cut]))
    try:
        with io.NpzArchive(path) as npz:
            for name in npz.names:
                npz.read(name)
    except io.FileError as exc:
        assert str(exc).startswith(str(path)) and "\n" not in str(exc)
