"""The ROS 2 bridges without Cyclone DDS: names, the clock, the refusal of an unauthenticated
console, and a deployment that imports no ``cyclonedds`` unless a bridge is asked for."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from rhmpc.runtime.ros2.names import RosClock, dds_topic, domain_id, endpoint, ros_name


def test_names() -> None:
    assert ros_name("PSM1/measured_js") == "/PSM1/measured_js"
    assert dds_topic("/tracker/poi") == "rt/tracker/poi"
    assert endpoint("ros2:/PSM1", "--console") == "/PSM1"
    for bad in ("/a//b", "/1a", "/a__b", "/a b", "/", "/a/"):
        with pytest.raises(ValueError, match="not a ROS 2 name"):
            ros_name(bad)
    with pytest.raises(ValueError, match="takes ros2:NAME"):
        endpoint("udp:/PSM1", "--console")
    assert domain_id({}) == 0 and domain_id({"ROS_DOMAIN_ID": "42"}) == 42
    with pytest.raises(ValueError, match="ROS_DOMAIN_ID"):
        domain_id({"ROS_DOMAIN_ID": "300"})


def test_the_clock_maps_ros_time_to_the_runs() -> None:
    epoch = time.clock_gettime_ns(time.CLOCK_MONOTONIC) - 3_000_000_000
    clock = RosClock(epoch)
    offset = time.clock_gettime_ns(time.CLOCK_REALTIME) - time.clock_gettime_ns(
        time.CLOCK_MONOTONIC)
    assert abs(clock.epoch_ros_ns() - (epoch + offset)) < 1e6  # the two reads' own gap
    for t in (0.0, 1.2345, -0.5):
        assert abs(clock.run_time(clock.ros_time(t)) - t) <= 1e-6
    assert abs(clock.now() - 3.0) < 0.1


def test_the_refusal_is_one_line(capsys) -> None:
    from rhmpc.cli import main

    assert main(["sil", "--duration", "2", "--console", "ros2:/PSM1"]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "--allow-unauthenticated" in line and "not authenticated" in line


@pytest.mark.slow
def test_sil_imports_no_cyclonedds_unless_asked() -> None:
    code = ("import sys\nfrom rhmpc.cli import build_parser\nimport rhmpc.runtime.deployment\n"
            "build_parser('sil').parse_args(['sil', '--tracker', 'ros2:/t'])\n"
            "print('cyclonedds' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "False"
