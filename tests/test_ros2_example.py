"""examples/ros2_base (zenoh-ros2-sdk teleop -> kinematic base -> odometry): NaNs on /cmd_vel, caught.

One star run with the example's test case: the base's speed limit lets a NaN
through, the odometry turns NaN, the CDR-field invariants catch it online and
offline, and every ROS 2 message of the log decodes with mcap-ros2-support.
"""

from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import zenoh_ros2_sdk  # noqa: F401  -- in the test extra; the ROS 2 client these tests run (missing: fail, not skip)
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory


EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "ros2_base"
CLI = [sys.executable, "-m", "astaa_deft.cli"]


def test_nan_on_cmd_vel_breaks_the_odometry_invariants_and_the_log_decodes(tmp_path):
    log = tmp_path / "run.mcap"
    run = subprocess.run([*CLI, "proxy", "--spec", str(EXAMPLE / "spec.yaml"), "--policy",
                          str(EXAMPLE / "nan_cmd_vel.xml"), "--record", str(log), "--duration", "5",
                          "--run-dir", str(tmp_path / "run")], capture_output=True, text=True, timeout=120)
    assert run.returncode == 1, run.stdout + run.stderr
    assert "finite_position (bound) on 'odom'" in run.stdout
    assert "set on 'cmd_vel'" in run.stdout and "linear.x" in run.stdout
    applied = int(re.search(r"mutations applied: (\d+)", run.stdout).group(1))
    assert applied >= 1

    offline = subprocess.run([*CLI, "check", str(log)], capture_output=True, text=True, timeout=60)
    assert offline.returncode == 1 and "finite_position" in offline.stdout

    decoded: dict[str, list] = {}
    with open(log, "rb") as stream:
        cdr_topics = sorted({c.topic for _s, c, _m in make_reader(stream).iter_messages()
                             if c.message_encoding == "cdr"})
        stream.seek(0)
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, _channel, _message, value in reader.iter_decoded_messages(topics=cdr_topics):
            decoded.setdefault(schema.name, []).append(value)
    assert set(decoded) == {"geometry_msgs/msg/Twist", "nav_msgs/msg/Odometry", "nav_msgs/msg/Path"}
    odometry = decoded["nav_msgs/msg/Odometry"]
    assert len(odometry) > 20 and odometry[0].header.frame_id == "odom"
    assert math.isnan(odometry[-1].pose.pose.position.x)  # NaN for good once it got in
    # The base's own record: it integrated a NaN command (its odometry twist is the command it used).
    assert any(math.isnan(o.twist.twist.linear.x) for o in odometry)
    # The log holds what the base got: exactly the Twists the test case set, no other NaN.
    assert sum(math.isnan(t.linear.x) for t in decoded["geometry_msgs/msg/Twist"]) == applied
