"""The one way out: a temporary file in the target's folder renamed over it; never through a
link, outside the folder given or onto an input; a failed write keeps the previous file."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rhmpc import io


def test_a_write_replaces_the_file_in_one_step(tmp_path: Path) -> None:
    target = tmp_path / "out.json"
    target.write_text("previous\n")
    target.chmod(0o640)
    io.write_text(target, "new\n")
    assert target.read_text() == "new\n" and (target.stat().st_mode & 0o777) == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.json"]  # no temporary left


def test_a_failed_write_keeps_the_previous_file_and_names_it(tmp_path: Path) -> None:
    target = tmp_path / "out.mat"
    target.write_text("previous\n")
    with pytest.raises(io.FileError, match=r"out\.mat: cannot write: No space left on "
                                                 r"device; the previous file is kept$"):
        with io.atomic_write(target) as f:
            f.write(b"partial")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert target.read_text() == "previous\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.mat"]


def test_an_error_of_the_content_discards_the_temporary_file(tmp_path: Path) -> None:
    with pytest.raises(ZeroDivisionError), io.atomic_write(tmp_path / "fig.png") as f:
        f.write(b"x")
        1 / 0  # noqa: B018
    assert list(tmp_path.iterdir()) == []


def test_a_link_is_never_written_through(tmp_path: Path) -> None:
    victim = tmp_path / "victim.txt"
    victim.write_text("keep\n")
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "rhmpc.h").symlink_to("../victim.txt")
    with pytest.raises(io.FileError, match=r"rhmpc\.h: a symbolic link \(to "
                                                 r"\.\./victim\.txt\); rhmpc writes nothing"):
        io.write_text(tmp_path / "out" / "rhmpc.h", "code\n", root=tmp_path / "out")
    assert victim.read_text() == "keep\n"


def test_nothing_is_written_outside_the_folder_given(tmp_path: Path) -> None:
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "osqp").symlink_to("../elsewhere")
    for name in ("osqp/src/a.c", "../b.c"):
        with pytest.raises(io.FileError):
            io.write_text(tmp_path / "out" / name, "x\n", root=tmp_path / "out")
    with pytest.raises(io.FileError, match="a symbolic link"):
        io.make_folder(tmp_path / "out" / "osqp" / "src", root=tmp_path / "out")
    assert list((tmp_path / "elsewhere").iterdir()) == []


def test_an_input_is_never_overwritten(tmp_path: Path) -> None:
    rec = tmp_path / "rec.mat"
    rec.write_bytes(b"recording")
    with pytest.raises(io.FileError, match=r"--out .*rec\.mat: is an input of this run"):
        io.check_output(rec, "--out", inputs=[rec])
    with io.tracking_inputs():
        io.read_bytes(rec)
        os.link(rec, tmp_path / "alias.mat")  # the same file by another name
        with pytest.raises(io.FileError, match="is an input of this run"):
            io.write_bytes(tmp_path / "alias.mat", b"result")
    assert rec.read_bytes() == b"recording"


@settings(max_examples=40, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(label=st.text(min_size=1, max_size=12), other=st.text(min_size=1, max_size=12))
def test_two_labels_never_share_a_file_name(tmp_path: Path, label: str, other: str) -> None:
    a, b = io.file_stem(label), io.file_stem(other)
    assert (a == b) == (label == other)
    assert "/" not in a and not a.startswith(".") and a.isascii()
