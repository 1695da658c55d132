"""ROS bags as recordings: every storage (rosbag2 MCAP and SQLite 3, as a folder or its file; ROS 1)
and every message type read, against the positions and stamps the bag was written with; header
stamps against receive times; stamps out of order, repeated, unset; gaps; the topics' errors; the
one reader's rules before ``rosbags`` opens a file."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from rhmpc import io
from rhmpc.sim.recordings import (
    RecordingError,
    RecordingWarning,
    is_bag,
    load_points,
    load_recording,
    survey,
    survey_lines,
)
from tests.sim.recordings.bags import (
    MARKER_ARRAY,
    OLD_TF,
    POINT_STAMPED,
    POSE_ARRAY,
    POSE_STAMPED,
    STRING,
    TF,
    TRANSFORM_STAMPED,
    messages,
    track,
    write_bag,
)

#: Each type read, its topic in the bags, and how it is read (--frame).
SINGLE = {"/pose": (POSE_STAMPED, {}), "/point": (POINT_STAMPED, {}),
          "/transform": (TRANSFORM_STAMPED, {"frame": "tool"}), "/tf": (TF, {"frame": "tool"})}
SEVERAL = {"/poses": POSE_ARRAY, "/markers": MARKER_ARRAY}
STORAGES = ("mcap", "sqlite3", "ros1", "mcap file", "db3 file")
N, POINTS = 60, 3


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> dict:
    """Per storage, a bag of every type read beside a distracting String topic, and what was
    written: stamps and receive times [ns], positions (N, POINTS, 3) [m]."""
    stamps, receive, z = track(np.random.default_rng(7), N, points=POINTS)
    rows = messages(stamps, receive, z)
    topics = {name: (kind, [(r, s, p[:1]) for r, s, p in rows])
              for name, (kind, _) in SINGLE.items()}
    topics |= {name: (kind, rows) for name, kind in SEVERAL.items()}
    topics["/camera/info"] = (STRING, rows[::5])
    d = tmp_path_factory.mktemp("bags")
    paths = {}
    for storage in ("mcap", "sqlite3", "ros1"):
        name = "rec.bag" if storage == "ros1" else f"rec_{storage}"
        paths[storage] = write_bag(d / name, storage, topics)
    paths["mcap file"] = paths["mcap"] / "rec_mcap.mcap"
    paths["db3 file"] = paths["sqlite3"] / "rec_sqlite3.db3"
    return {"paths": paths, "stamps": stamps, "receive": receive, "z": z}


@pytest.mark.parametrize("storage", STORAGES)
@pytest.mark.parametrize("topic", list(SINGLE))
def test_each_storage_and_type_gives_the_positions_at_their_stamps(written: dict, storage: str,
                                                                   topic: str) -> None:
    path = written["paths"][storage]
    assert is_bag(path)
    rec = load_recording(path, topic=topic, **SINGLE[topic][1])
    t = (written["stamps"] - written["stamps"][0]) * 1e-9
    np.testing.assert_allclose(rec.t, t, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.z, written["z"][:, 0], rtol=0, atol=1e-15)
    assert rec.units == "m" and rec.units_origin == "default" and rec.time_unit == "s"
    assert rec.sample_rate == pytest.approx(25.0, rel=1e-12)


@pytest.mark.parametrize("storage", STORAGES)
@pytest.mark.parametrize("topic", list(SEVERAL))
def test_arrays_give_each_point_its_trajectory(written: dict, storage: str, topic: str) -> None:
    path = written["paths"][storage]
    points = load_points(path, topic=topic)  # markers come in reverse id order, one deleted
    assert len(points) == POINTS
    for k, rec in enumerate(points):
        np.testing.assert_allclose(rec.z, written["z"][:, k], rtol=0, atol=1e-15)
    one = load_recording(path, topic=topic, point=2)
    np.testing.assert_allclose(one.z, written["z"][:, 1], rtol=0, atol=1e-15)
    with pytest.raises(RecordingError, match="holds 3 tracked points; choose one with --poi N"):
        load_recording(path, topic=topic)


def test_ros1_tf_before_tf2(tmp_path: Path) -> None:
    stamps, receive, z = track(np.random.default_rng(4), N)
    path = write_bag(tmp_path / "old.bag", "ros1",
                     {"/tf": (OLD_TF, messages(stamps, receive, z))})
    rec = load_recording(path, frame="/tool")
    np.testing.assert_allclose(rec.z, z[:, 0], rtol=0, atol=1e-15)


def test_a_leading_slash_and_a_ros1_frame_name_may_differ(written: dict) -> None:
    path = written["paths"]["ros1"]
    a = load_recording(path, topic="tf", frame="/tool")
    b = load_recording(path, topic="/tf", frame="tool")
    np.testing.assert_array_equal(a.z, b.z)


def test_the_topics_errors_name_the_topics_present(written: dict) -> None:
    path = written["paths"]["mcap"]
    every = r"the bag holds /camera/info \(std_msgs/String, 12\), /markers .*/transform"
    with pytest.raises(RecordingError, match=r"no topic /nope; " + every):
        load_recording(path, topic="/nope")
    with pytest.raises(RecordingError, match=r"topic /camera/info is std_msgs/String, which is "
                       r"not read .*; " + every):
        load_recording(path, topic="/camera/info")
    with pytest.raises(RecordingError, match=r"name the POI's topic with --topic NAME; " + every):
        load_recording(path)
    with pytest.raises(RecordingError, match=r"--frame applies to tf2_msgs/TFMessage"):
        load_recording(path, topic="/pose", frame="tool")
    with pytest.raises(RecordingError, match=r"transforms to several frames: name one with "
                       r"--frame NAME \(camera, tool\)"):
        load_recording(path, topic="/tf")
    with pytest.raises(RecordingError, match=r"no transform to frame hand \(it holds camera, "
                       r"tool\)"):
        load_recording(path, topic="/tf", frame="hand")
    with pytest.raises(RecordingError, match=r"--var, --rows, --cols and --rate apply to \.mat"):
        load_recording(path, topic="/pose", rate=25.0)


def test_one_topic_of_a_type_read_needs_no_name(tmp_path: Path) -> None:
    stamps, receive, z = track(np.random.default_rng(3), N)
    rows = messages(stamps, receive, z)
    path = write_bag(tmp_path / "one", "mcap", {"/camera/info": (STRING, rows),
                                                "/tracker/poi": (POSE_STAMPED, rows)})
    named = load_recording(path, topic="/tracker/poi")
    np.testing.assert_array_equal(load_recording(path).z, named.z)
    only = write_bag(tmp_path / "none", "mcap", {"/camera/info": (STRING, rows)})
    with pytest.raises(RecordingError, match=r"no topic of a type read \(geometry_msgs/"
                       r"PoseStamped, .*\); the bag holds /camera/info \(std_msgs/String, 60\)$"):
        load_recording(only)


def test_units_say_what_the_positions_are_in(written: dict) -> None:
    path = written["paths"]["mcap"]
    with pytest.warns(RecordingWarning, match="if the file is in metres, pass --units m"):
        rec = load_recording(path, topic="/pose", units="mm")  # metres read as millimetres
    np.testing.assert_allclose(rec.z, written["z"][:, 0] * 1e-3, rtol=1e-15)
    assert rec.units_origin == "option"


def test_the_stamps_are_the_times_when_the_receive_times_disagree(tmp_path: Path) -> None:
    """Receive times lagging 0–120 ms (three periods): the recording's times are the stamps,
    not the receive times; the survey states the lag from the messages as written."""
    stamps, receive, z = track(np.random.default_rng(11), N, lag=(0.0, 0.12))
    path = write_bag(tmp_path / "lag", "mcap", {"/p": (POSE_STAMPED, messages(stamps, receive, z))})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = load_recording(path)
    order = np.argsort(receive, kind="stable")  # the order the bag holds them in
    late = int(np.sum(stamps[order][1:] < np.maximum.accumulate(stamps[order])[:-1]))
    assert late > 0 and any("put in stamp order" in str(w.message) for w in caught)
    np.testing.assert_allclose(rec.t, (stamps - stamps[0]) * 1e-9, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.z, z[:, 0], rtol=0, atol=1e-15)
    (row,) = survey(path)["topics"]
    assert row["out_of_order"] == late and row["repeated"] == 0
    lag_ms = (receive - stamps) * 1e-6
    assert row["lag_ms"]["p50"] == pytest.approx(np.median(lag_ms), abs=1e-3)
    assert row["lag_ms"]["max"] == pytest.approx(lag_ms.max(), abs=1e-3)


def test_stamps_out_of_order_and_repeated_are_reordered_and_flagged(tmp_path: Path) -> None:
    stamps, receive, z = track(np.random.default_rng(5), N)
    rows = messages(stamps, receive, z)
    rows[10], rows[11] = (rows[10][0], rows[11][1], rows[11][2]), (rows[11][0], rows[10][1],
                                                                   rows[10][2])  # swapped
    rows[30] = (rows[30][0], rows[29][1], rows[29][2] + 1.0)  # repeats 29's stamp: left out
    path = write_bag(tmp_path / "order", "sqlite3", {"/p": (POSE_STAMPED, rows)})
    with pytest.warns(RecordingWarning) as caught:
        rec = load_recording(path)
    text = " ".join(str(w.message) for w in caught)
    assert "1 message(s) received out of their stamps' order" in text
    assert "1 message(s) repeat an earlier one's stamp, left out" in text
    keep = np.delete(np.arange(N), 30)
    np.testing.assert_allclose(rec.t, (stamps[keep] - stamps[0]) * 1e-9, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rec.z, z[keep, 0], rtol=0, atol=1e-15)
    doc = survey(path)
    assert (doc["topics"][0]["out_of_order"], doc["topics"][0]["repeated"]) == (1, 1)
    assert "stamps not monotonic: 1 received out of order" in "\n".join(survey_lines(doc))


def test_a_ten_second_gap_is_reported(tmp_path: Path) -> None:
    stamps, receive, z = track(np.random.default_rng(9), N)
    jump = 10 * 10**9  # 10 s without a sample after sample 29
    stamps[30:] += jump
    receive[30:] += jump
    rows = messages(stamps, receive, z)
    path = write_bag(tmp_path / "gap.bag", "ros1", {"/p": (POSE_STAMPED, rows)})
    with pytest.warns(RecordingWarning, match=r"1 gap\(s\) of 1 s or more in the sample times, "
                      r"10\.04 s in all; the longest 10\.04 s from t = 1\.16 s"):
        load_recording(path)
    (row,) = survey(path)["topics"]
    assert row["gaps"] == {"count": 1, "missing": 250, "seconds": 10.04, "longest": 10.04,
                           "at": 1.16}
    assert "gaps: 1 (10.04 s in all, about 250 samples missing" in survey_lines(survey(path))[-2]


def test_unset_stamps(tmp_path: Path) -> None:
    stamps, receive, z = track(np.random.default_rng(2), N)
    zero = np.zeros_like(stamps)
    path = write_bag(tmp_path / "unset", "mcap", {"/p": (POSE_STAMPED, messages(zero, receive, z))})
    with pytest.warns(RecordingWarning, match="no message has its header stamp set"):
        rec = load_recording(path)
    np.testing.assert_allclose(rec.t, (receive - receive[0]) * 1e-9, rtol=0, atol=1e-12)
    assert survey(path)["topics"][0]["stamps"] == "receive"
    some = stamps.copy()
    some[[5, 6]] = 0
    path = write_bag(tmp_path / "some", "mcap", {"/p": (POSE_STAMPED, messages(some, receive, z))})
    with pytest.warns(RecordingWarning, match=r"2 message\(s\) without a header stamp"):
        rec = load_recording(path)
    assert rec.t.size == N - 2


def test_reading_a_bag_makes_its_files_inputs_of_the_run(written: dict) -> None:
    path = written["paths"]["mcap"]
    with io.tracking_inputs():
        load_recording(path, topic="/pose")
        read = set(io.reader.inputs_read().values())
    assert {str(path / "metadata.yaml"), str(path / "rec_mcap.mcap")} <= read


# The one reader's rules, before rosbags opens anything: one line naming the file.

def _folder(tmp_path: Path, written: dict, metadata: str | None = None) -> Path:
    """A copy of the MCAP bag's folder, its metadata.yaml replaced by ``metadata``."""
    src = written["paths"]["mcap"]
    d = tmp_path / "copy"
    d.mkdir()
    (d / "rec_mcap.mcap").write_bytes((src / "rec_mcap.mcap").read_bytes())
    text = (src / "metadata.yaml").read_text() if metadata is None else metadata
    (d / "metadata.yaml").write_text(text)
    return d


def test_a_storage_file_that_is_a_device_is_refused(tmp_path: Path, written: dict) -> None:
    d = _folder(tmp_path, written)
    (d / "rec_mcap.mcap").unlink()
    os.symlink("/dev/zero", d / "rec_mcap.mcap")
    with pytest.raises(RecordingError, match=r"rec_mcap\.mcap: a character device, not a "
                       "regular file"):
        load_recording(d, topic="/pose")


def test_a_bag_larger_than_its_bound_is_refused(written: dict, monkeypatch) -> None:
    monkeypatch.setitem(io.FILE_BYTES, "bag", 1000)
    for path in (written["paths"]["ros1"], written["paths"]["mcap"]):
        with pytest.raises(RecordingError, match=r"larger than a bag may be \(1 kB\)"):
            load_recording(path, topic="/pose")


def test_malformed_bags_are_one_line(tmp_path: Path, written: dict) -> None:
    junk = tmp_path / "junk.bag"
    junk.write_bytes(np.random.default_rng(1).bytes(4096))
    with pytest.raises(RecordingError, match=r"junk\.bag: not a readable ROS bag \("):
        load_recording(junk)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes((written["paths"]["mcap file"]).read_bytes()[:5000])
    with pytest.raises(RecordingError, match=r"cut\.mcap: not a readable ROS bag \("):
        load_recording(cut, topic="/pose")
    missing = tmp_path / "missing.db3"
    with pytest.raises(RecordingError, match=r"missing\.db3: no such file"):
        load_recording(missing)


@pytest.mark.parametrize(("metadata", "error"), [
    ("a: [", r"metadata\.yaml: not valid YAML"),
    ("other: 1\n", r"metadata\.yaml: no rosbag2_bagfile_information"),
    ("x: " + "[" * 100 + "]" * 100, r"metadata\.yaml: nested deeper than 64 levels"),
    ("rosbag2_bagfile_information:\n  compression_mode: FILE\n",
     r"copy: its files are compressed whole, which is not read; convert it"),
])
def test_bad_metadata_is_one_line(tmp_path: Path, written: dict, metadata: str,
                                  error: str) -> None:
    with pytest.raises(RecordingError, match=error) as caught:
        load_recording(_folder(tmp_path, written, metadata), topic="/pose")
    assert "\n" not in str(caught.value)


def test_a_folder_cut_short_names_its_file(tmp_path: Path, written: dict) -> None:
    d = _folder(tmp_path, written)
    (d / "metadata.yaml").unlink()
    with pytest.raises(RecordingError, match=r"a rosbag2 folder without its metadata\.yaml "
                       r"\(a recording cut short\?\): give its file, .*rec_mcap\.mcap"):
        load_recording(d, topic="/pose")
    np.testing.assert_array_equal(load_recording(d / "rec_mcap.mcap", topic="/pose").z,
                                  written["z"][:, 0])


def test_a_folder_that_is_no_bag_is_a_folder(tmp_path: Path) -> None:
    assert not is_bag(tmp_path)
    with pytest.raises(RecordingError, match="a folder, not a regular file; give a file"):
        load_recording(tmp_path)
