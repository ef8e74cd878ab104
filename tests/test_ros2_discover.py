"""`spec discover` on a live ROS 2 system (zenoh-ros2-sdk nodes in a passive run), its pure parts, and its errors.

Also, from the same passive run: the log's publish times are the rmw_zenoh
attachments' source timestamps, and the discovered spec runs attached to the
live system (``proxy --no-launch --passive``).
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import zenoh_ros2_sdk  # noqa: F401  -- in the test extra; the ROS 2 client these tests run (missing: fail, not skip)
from mcap.reader import make_reader

from astaa_deft.engine.bus.zenoh_config import free_port
from astaa_deft.io.codecs.rmw_attachment import parse_attachment
from astaa_deft.analysis.ros2.graph import build_graph, parse_token
from astaa_deft.analysis.ros2.skeleton import spec_skeleton
from astaa_deft.engine.spec.loader import load_spec, load_spec_text
from astaa_deft.io.ros2.types import shared_types


NODE = Path(__file__).parent / "sut" / "ros2" / "sdk_node.py"
TWIST_HASH = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
TWIST_DDS = "geometry_msgs::msg::dds_::Twist_"
CLI = [sys.executable, "-m", "astaa_deft.cli"]

SPEC = """\
name: sdk_passive
zenoh: {endpoints: ["tcp/127.0.0.1:@PORT@"]}
modules:
  - name: listener
    command: ["{python}", "@NODE@", "listener", "--messages", "@MESSAGES@", "--out", "{run_dir}/listener.out"]
    ready: {log: "listener: subscribed"}
  - name: talker
    command: ["{python}", "@NODE@", "talker", "--messages", "@MESSAGES@", "--out", "{run_dir}/talker.out",
              "--count", "4000", "--rate", "40"]
channels:
  - {name: cmd_vel, topic: /cmd_vel, type: geometry_msgs/msg/Twist, encoding: cdr, producer: talker,
     consumers: [listener]}
"""


def test_tokens_parse_into_a_graph_and_a_spec_that_checks():
    keys = [
        "@ros2_lv/0/aa11/0/0/NN/%/%/teleop",
        f"@ros2_lv/0/aa11/0/1/MP/%/%/teleop/%cmd_vel/{TWIST_DDS}/{TWIST_HASH}/::,7:,:,:,,",
        "@ros2_lv/0/bb22/0/0/NN/%/%robot1/base",
        f"@ros2_lv/0/bb22/0/3/MS/%/%robot1/base/%cmd_vel/{TWIST_DDS}/{TWIST_HASH}/::,7:,:,:,,",
        "@ros2_lv/0/bb22/0/4/MP/%/%robot1/base/%robot1%odom/nav_msgs::msg::dds_::Odometry_/"
        f"{shared_types().rihs01('nav_msgs/msg/Odometry')}/::,7:,:,:,,",
        "@ros2_lv/0/bb22/0/5/MP/%/%robot1/base/%rosout/rcl_interfaces::msg::dds_::Log_/RIHS01_x/::,7:,:,:,,",
        "@ros2_lv/0/cc33/0/1/MP/%/%/odd/%status/my_pkg::msg::dds_::Status_/RIHS01_y/::,7:,:,:,,",
        "@ros2_lv/3/dd44/0/0/NN/%/%/other_domain",
        "some/other/token",
    ]
    entities = [e for e in map(parse_token, keys) if e is not None]
    assert entities[2].namespace == "/robot1" and entities[2].node_path == "/robot1/base"
    assert entities[4].topic == "/robot1/odom"
    graph = build_graph(entities, 0)
    assert graph.nodes == ["/teleop", "/robot1/base", "/odd"]
    skeleton = spec_skeleton(graph, shared_types(), name="found", connect=["tcp/127.0.0.1:7447"])
    spec = load_spec_text(skeleton.text)
    assert [m.name for m in spec.modules] == ["teleop", "robot1_base", "odd"]
    cmd = spec.channel("cmd_vel")
    assert (cmd.producer, cmd.consumers, cmd.type) == ("teleop", ("robot1_base",), "geometry_msgs/msg/Twist")
    assert cmd.key == f"0/cmd_vel/{TWIST_DDS}/{TWIST_HASH}"
    assert spec.channel("robot1_odom").producer == "robot1_base"
    assert spec.module("teleop").ready.channel == "cmd_vel" and spec.module("odd").ready.delay == 1.0
    assert "std_msgs/msg/Header.stamp" in spec.brittle
    assert [c.name for c in spec.channels] == ["cmd_vel", "robot1_odom"]  # no /rosout, no unknown type
    assert any("my_pkg::msg::dds_::Status_" in note for note in skeleton.notes)


def test_a_hash_mismatch_is_noted_and_the_observed_key_kept():
    keys = ["@ros2_lv/0/aa/0/0/NN/%/%/teleop",
            f"@ros2_lv/0/aa/0/1/MP/%/%/teleop/%cmd_vel/{TWIST_DDS}/RIHS01_{'0' * 64}/::,7:,:,:,,"]
    graph = build_graph([parse_token(k) for k in keys])
    skeleton = spec_skeleton(graph, shared_types(), name="found", connect=["tcp/127.0.0.1:7447"])
    assert len(skeleton.notes) == 1 and "type hash mismatch" in skeleton.notes[0]
    spec = load_spec_text(skeleton.text)
    assert spec.channel("cmd_vel").key == f"0/cmd_vel/{TWIST_DDS}/RIHS01_{'0' * 64}"


def test_discovery_with_no_ros2_nodes_is_one_clear_error(tmp_path):
    port = free_port()
    router = subprocess.Popen([sys.executable, "-m", "astaa_deft.engine.bus.router", "--listen", f"tcp/127.0.0.1:{port}"],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert router.stdout.readline().strip() == "ready"
        done = subprocess.run([*CLI, "spec", "discover", "--connect", f"tcp/127.0.0.1:{port}", "--seconds", "1",
                               "-o", str(tmp_path / "spec.yaml")], capture_output=True, text=True, timeout=60)
    finally:
        router.terminate()
        router.wait(timeout=10)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "no ROS 2 nodes" in lines[0] and "Traceback" not in done.stderr
    assert not (tmp_path / "spec.yaml").exists()


def test_discover_a_live_system_then_record_it_with_the_discovered_spec(tmp_path):
    messages = tmp_path / "msgs"
    shared_types().write_definitions(["geometry_msgs/msg/Twist"], messages)
    port = free_port()
    spec = tmp_path / "spec.yaml"
    spec.write_text(SPEC.replace("@PORT@", str(port)).replace("@NODE@", str(NODE))
                    .replace("@MESSAGES@", str(messages)))
    run_dir, log = tmp_path / "run", tmp_path / "run.mcap"
    system = subprocess.Popen([*CLI, "proxy", "--spec", str(spec), "--passive", "--record", str(log),
                               "--run-dir", str(run_dir), "--duration", "90"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while not (run_dir / "talker.out").exists() or not (run_dir / "talker.out").read_text():
            assert system.poll() is None and time.monotonic() < deadline, system.communicate()
            time.sleep(0.2)
        found = tmp_path / "found.yaml"
        done = subprocess.run([*CLI, "spec", "discover", "--connect", f"tcp/127.0.0.1:{port}", "--seconds", "1.5",
                               "-o", str(found), "--name", "found"], capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr
        checked = subprocess.run([*CLI, "spec", "check", str(found)], capture_output=True, text=True, timeout=60)
        assert checked.returncode == 0, checked.stderr
        # The discovered spec runs: attached to the live system, it records the same topic.
        attached = subprocess.run([*CLI, "proxy", "--spec", str(found), "--no-launch", "--passive", "--record",
                                   str(tmp_path / "attached.mcap"), "--duration", "1.5"],
                                  capture_output=True, text=True, timeout=60)
        assert attached.returncode == 0, attached.stderr
        time.sleep(2.0)  # let at least 80 messages reach the passive log
    finally:
        system.send_signal(signal.SIGINT)  # the run ends cleanly on Ctrl-C (its log finished)
        out, err = system.communicate(timeout=60)
    assert system.returncode == 0, err
    discovered = load_spec(found)
    assert {m.name for m in discovered.modules} == {"teleop", "base"}
    channel = discovered.channel("cmd_vel")
    assert (channel.producer, channel.consumers, channel.type) == ("teleop", ("base",), "geometry_msgs/msg/Twist")
    assert channel.key == load_spec(spec).channel("cmd_vel").key
    with open(tmp_path / "attached.mcap", "rb") as stream:
        topics = [c.topic for _s, c, _m in make_reader(stream).iter_messages() if c.message_encoding == "cdr"]
    assert topics and set(topics) == {channel.key}

    # Passive log: publish_time of each ROS 2 message is its attachment's source timestamp.
    sent = [json.loads(line) for line in (run_dir / "talker.out").read_text().splitlines()]
    stamps = {bytes.fromhex(m["payload"]): parse_attachment(bytes.fromhex(m["attachment"])).source_time_ns
              for m in sent}
    with open(log, "rb") as stream:
        recorded = [(m.data, m.publish_time) for _s, c, m in make_reader(stream).iter_messages()
                    if c.message_encoding == "cdr"]
    assert len(recorded) >= 80
    assert all(publish_time == stamps[data] for data, publish_time in recorded)
