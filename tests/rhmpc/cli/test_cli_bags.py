"""ROS bags on the command line: `data show` lists a bag's topics and flags its gaps and stamps,
every command that reads a recording reads a bag's topic (the same numbers as the same samples
in an NPZ file), a bad topic is one line naming the topics present; a gap in any recording is
reported by `data show` and by the run."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rhmpc.cli import build_parser, main
from rhmpc.cli.simulate import config_from_args
from rhmpc.sim.recordings import save_recording
from tests.sim.recordings.bags import POSE_ARRAY, POSE_STAMPED, STRING, messages, track, write_bag

N = 150  # 6 s at 25 Hz


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> dict:
    """A rosbag2 (MCAP) of a POI, three tracked points and a distracting topic, and an NPZ file
    of the POI's samples as the bag's stamps give them."""
    stamps, receive, z = track(np.random.default_rng(21), N, points=3)
    rows = messages(stamps, receive, z)
    d = tmp_path_factory.mktemp("cli-bags")
    path = write_bag(d / "rec", "mcap", {
        "/tracker/poi": (POSE_STAMPED, [(r, s, p[:1]) for r, s, p in rows]),
        "/tracker/points": (POSE_ARRAY, rows), "/camera/info": (STRING, rows[::10])})
    npz = save_recording(d / "poi.npz", (stamps - stamps[0]) * 1e-9, z[:, 0])
    return {"path": path, "npz": npz}


def test_data_show_lists_the_topics(bag: dict, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["data", "show", str(bag["path"])]) == 0
    out = capsys.readouterr().out
    for line in ("/camera/info                 std_msgs/String                          15",
                 "/tracker/points              geometry_msgs/PoseArray                 150"
                 "       25     5.96      3"):
        assert line in out
    assert "/tracker/poi                 header stamps, received" in out and "no gap" in out
    assert main(["data", "show", str(bag["path"]), "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [r["topic"] for r in doc["topics"]] == ["/camera/info", "/tracker/poi",
                                                   "/tracker/points"]
    assert main(["data", "show", str(bag["path"]), "--topic", "/tracker/points", "--poi",
                 "1"]) == 0
    out = capsys.readouterr().out
    assert "sample rate       25 Hz" in out and "gaps              none" in out


def test_a_topic_that_is_not_there_is_one_line(bag: dict,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--data", str(bag["path"]), "--topic", "/nope", "--duration",
                 "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no topic /nope; the bag holds /camera/info" in err[0]
    assert "/tracker/poi (geometry_msgs/PoseStamped, 150)" in err[0]
    assert main(["simulate", "--topic", "/tracker/poi"]) == 2
    assert "--topic, --frame, --poi and --split need --data FILE" in capsys.readouterr().err
    assert main(["predict", "--data", str(bag["npz"]), "--topic", "/tracker/poi"]) == 2
    assert "--topic and --frame apply to ROS bags" in capsys.readouterr().err


def on_bag_and_npz(bag: dict, capsys, command: str, *options: str) -> list[dict]:
    """The JSON documents of ``rhmpc COMMAND --data BAG --topic /tracker/poi OPTIONS`` and of the
    same on the NPZ file of the same samples."""
    docs = []
    for data in (["--data", str(bag["path"]), "--topic", "/tracker/poi"],
                 ["--data", str(bag["npz"])]):
        assert main([command, *data, *options, "--json"]) == 0
        docs.append(json.loads(capsys.readouterr().out))
    return docs


def test_predict_reads_the_bag_as_the_same_samples(bag: dict,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    docs = on_bag_and_npz(bag, capsys, "predict", "--predictors", "hold,one-step", "--split",
                          "50:150")
    rows = [d["results"] for d in docs]
    assert [r["predictor"] for r in rows[0]] == [r["predictor"] for r in rows[1]]
    for a, b in zip(*rows, strict=True):
        assert a["rms_error_mm"] == pytest.approx(b["rms_error_mm"], rel=1e-9)


@pytest.mark.slow
def test_simulate_with_a_split_reads_the_bag_as_the_same_samples(
        bag: dict, capsys: pytest.CaptureFixture[str]) -> None:
    docs = on_bag_and_npz(bag, capsys, "simulate", "--split", "100:150", "--predictor",
                          "one-step")
    assert docs[0]["rms_error_mm"] == pytest.approx(docs[1]["rms_error_mm"], rel=1e-6)


def test_compare_reads_a_point_of_the_bag(bag: dict, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["compare", "--data", str(bag["path"]), "--topic", "/tracker/points", "--poi",
                 "2", "--predictors", "hold", "--duration", "1", "--json"]) == 0
    (run,) = json.loads(capsys.readouterr().out)["runs"]
    assert run["scenario"] == "rec:p2" and run["rms_error_mm"] > 0


def test_sil_takes_the_topic_into_the_run_settings(bag: dict) -> None:
    args = build_parser("sil").parse_args(["sil", "--data", str(bag["path"]), "--topic",
                                           "/tracker/points", "--poi", "3", "--duration", "1"])
    config = config_from_args(args)
    assert config.data_read == {"topic": "/tracker/points", "point": 3}
    assert config.sensor == "recorded"


def test_a_gap_in_a_csv_is_reported(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    t = np.arange(200) / 25.0
    t[100:] += 10.0  # 10 s without a sample
    z = 2e-3 * np.sin(2 * np.pi * 1.2 * t)[:, None] * np.ones(3)
    path = save_recording(tmp_path / "gap.csv", t, z)
    assert main(["data", "show", str(path)]) == 0
    captured = capsys.readouterr()
    assert ("gaps              1 (10.04 s in all, about 250 samples missing); the longest "
            "10.04 s from t = 3.96 s") in captured.out
    assert "gap(s) of 1 s or more in the sample times" in captured.err
    assert main(["simulate", "--data", str(path), "--duration", "1", "--predictor", "hold"]) == 0
    assert "rhmpc simulate: warning: " in capsys.readouterr().err
