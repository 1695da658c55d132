"""The one model format and its loader: whatever a file holds, it loads as saved or is refused in
one line naming it, before any array it declares is allocated (hypothesis over damaged and
altered files)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rhmpc import io
from rhmpc.predictors import make_predictor
from rhmpc.predictors.learned.modelfile import VERSION, ModelFile
from rhmpc.predictors.registry import load_model
from tests.predictors.helpers import feed, tracked_points

DT = 0.04
PROPERTY = settings(max_examples=40, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def stream() -> np.ndarray:
    return tracked_points(300, DT, seed=3, noise=20e-6)


@pytest.fixture(scope="module")
def ridge_file(stream, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("models") / "rec.st-ridge.npz"
    make_predictor("st-ridge", DT).fit(stream[:250]).save(path)
    return path


def _members(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as f:
        return {k: f[k] for k in f.files}


def _write(path: Path, members: dict, header: dict | None = None) -> Path:
    if header is not None:
        members = {**members, "header": np.array(json.dumps(header))}
    with open(path, "wb") as f:
        np.savez(f, **members)
    return path


def _refused(path: Path, kind="st-ridge") -> str:
    with pytest.raises(ValueError) as info:
        make_predictor(kind, DT, model=str(path))
    text = str(info.value)
    assert text.startswith(str(path)) and "\n" not in text, text
    return text


def test_a_model_loads_as_saved_and_declares_itself(stream, ridge_file) -> None:
    p = load_model(ridge_file, "st-ridge", dt=DT)
    q = make_predictor("st-ridge", DT).fit(stream[:250])
    np.testing.assert_array_equal(feed(p, stream, 4), feed(q, stream, 4))
    with ModelFile(ridge_file) as saved:
        assert (saved.kind, saved.dt, saved.points, saved.dim) == ("st-ridge", DT, 4, 3)
        assert saved.shapes["orders"] == ((4,), np.dtype("<i8"))
    header = json.loads(str(_members(ridge_file)["header"]))
    assert header["version"] == VERSION and header["format"] == "rhmpc-model"


def test_the_kind_and_the_period_asked_for_are_checked(ridge_file) -> None:
    assert "a 'st-ridge' model, not 'ridge'" in _refused(ridge_file, "ridge")
    with pytest.raises(ValueError, match=r"fitted at dt = 0\.04 s; this predictor runs at 0\.01"):
        load_model(ridge_file, dt=0.01)


def test_an_empty_file_a_fifo_and_a_folder_are_one_line(tmp_path: Path) -> None:
    empty = tmp_path / "empty.npz"
    empty.touch()
    assert _refused(empty).endswith("an empty file (0 bytes), not a saved model")
    os.mkfifo(tmp_path / "fifo.npz")
    assert "named pipe (FIFO)" in _refused(tmp_path / "fifo.npz")
    assert "a folder" in _refused(tmp_path)


def test_windows_of_a_billion_samples_are_refused_before_allocation(ridge_file,
                                                                     tmp_path: Path) -> None:
    members = _members(ridge_file)
    header = json.loads(str(members.pop("header")))
    members["orders"] = np.array([10**9] * 4)  # the file's header still says (4,) int64
    assert "windows [1000000000" in _refused(_write(tmp_path / "huge.npz", members, header))
    members["orders"] = np.array([10**9])  # the shape the header declares, no longer
    assert "array 'orders' holds int64 (1,)" in _refused(_write(tmp_path / "h.npz", members,
                                                                header))


def test_a_file_without_the_header_or_of_a_newer_version(ridge_file, tmp_path: Path) -> None:
    members = _members(ridge_file)
    header = json.loads(str(members.pop("header")))
    assert "not a saved rhmpc model (no header" in _refused(_write(tmp_path / "old.npz",
                                                                   members))
    header["version"] = VERSION + 1
    assert "written by a newer rhmpc" in _refused(_write(tmp_path / "new.npz", members, header))


def _alter(header: dict, members: dict, what: str, value) -> None:
    """One alteration of a saved model's header or arrays."""
    if what == "field":
        key, new = value
        header[key] = new
    elif what == "setting":
        key, new = value
        header["settings"][key] = new
    elif what == "shape":
        name, shape = value
        header["arrays"].setdefault(name, {"dtype": "<f8"})["shape"] = shape
    elif what == "array":
        name, shape = value
        members[name] = np.zeros(shape)
    elif what == "drop":
        members.pop(value, None)


FIELDS = st.sampled_from(["kind", "version", "dt", "points", "dim", "format", "settings",
                          "arrays"])
VALUES = st.one_of(st.none(), st.booleans(), st.integers(-10**12, 10**12),
                   st.floats(allow_nan=True), st.text(max_size=8), st.lists(st.integers(),
                                                                             max_size=3))
ALTERATIONS = st.one_of(
    st.tuples(st.just("field"), st.tuples(FIELDS, VALUES)),
    st.tuples(st.just("setting"), st.tuples(st.sampled_from(["leads", "windows", "alphas",
                                                             "validation", "nosuch"]), VALUES)),
    st.tuples(st.just("shape"), st.tuples(st.sampled_from(["orders", "W0", "W3", "alphas"]),
                                          st.lists(st.integers(-1, 10**12), max_size=3))),
    st.tuples(st.just("array"), st.tuples(st.sampled_from(["orders", "W0", "W9", "alphas"]),
                                          st.lists(st.integers(0, 40), max_size=2))),
    st.tuples(st.just("drop"), st.sampled_from(["orders", "W1", "header", "validation_rms"])),
)


@PROPERTY
@given(alterations=st.lists(ALTERATIONS, min_size=1, max_size=3))
def test_an_altered_model_loads_or_is_one_line(ridge_file, tmp_path: Path,
                                               alterations) -> None:
    members = _members(ridge_file)
    header = json.loads(str(members.pop("header")))
    for what, value in alterations:
        _alter(header, members, what, value)
    path = _write(tmp_path / "altered.npz", members, header)
    try:
        p = make_predictor("st-ridge", DT, model=str(path))
    except ValueError as exc:
        assert str(exc).startswith(str(path)) and "\n" not in str(exc), exc
    else:
        assert p.fitted and all(W.size < 10**6 for W in p.model["W"])


@PROPERTY
@given(cut=st.integers(1, 4000), flip=st.integers(0, 4000), byte=st.integers(0, 255))
def test_a_damaged_model_loads_or_is_one_line(ridge_file, tmp_path: Path, cut: int, flip: int,
                                              byte: int) -> None:
    data = bytearray(ridge_file.read_bytes())
    data[flip % len(data)] = byte
    path = tmp_path / "damaged.npz"
    path.write_bytes(bytes(data[: max(0, len(data) - cut)]))
    try:
        make_predictor("st-ridge", DT, model=str(path))
    except ValueError as exc:
        assert str(exc).startswith(str(path)) and "\n" not in str(exc), exc


def test_a_network_file_holds_numbers_only_and_refuses_other_shapes(stream,
                                                                    tmp_path: Path) -> None:
    pytest.importorskip("torch", reason="the neural predictors need PyTorch (rhmpc[learned])")
    p = make_predictor("lstm", DT, hidden=4, epochs=2, validation=0.0).fit(stream[:250])
    path = tmp_path / "net.npz"
    p.save(path)
    members = _members(path)
    assert all(v.dtype.kind in "fiU" for v in members.values())
    header = json.loads(str(members.pop("header")))
    for hidden in (10**5, 10**9):  # shapes no file holds: refused without building them
        header["settings"]["hidden"] = hidden
        text = _refused(_write(tmp_path / "big.npz", members, header), "lstm")
        assert "its settings make it" in text or "a network no file holds" in text


def test_a_network_fitted_on_one_second_warns(stream) -> None:
    pytest.importorskip("torch", reason="the neural predictors need PyTorch (rhmpc[learned])")
    from rhmpc.predictors.learned.fitted import FitWarning

    with pytest.warns(FitWarning, match=r"lstm is fitted on 25 samples \(1 s\), less than 5 s"):
        make_predictor("lstm", DT, hidden=4, epochs=1, validation=0.0).fit(stream[:25])


def test_the_saved_file_is_atomic_and_never_through_a_link(stream, tmp_path: Path) -> None:
    p = make_predictor("ridge", DT).fit(stream[:250])
    (tmp_path / "victim.npz").write_text("keep")
    (tmp_path / "m.npz").symlink_to("victim.npz")
    with pytest.raises(io.FileError, match="a symbolic link"):
        p.save(tmp_path / "m.npz")
    assert (tmp_path / "victim.npz").read_text() == "keep"
