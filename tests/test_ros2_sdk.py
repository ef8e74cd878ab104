"""ROS 2 nodes written with zenoh-ros2-sdk, through the star proxy: bytes, attachments, a CDR field rewritten, the log.

Real subprocesses on loopback (multicast scouting off in every config the tool
writes); the SDK gets its message definitions from a local directory and a
proxy on 127.0.0.1:9 so that nothing it might try to download leaves the machine.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import zenoh_ros2_sdk  # noqa: F401  -- in the test extra; the ROS 2 client these tests run (missing: fail, not skip)
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from astaa_deft.io.codecs import get_codec
from astaa_deft.io.codecs.rmw_attachment import parse_attachment
from astaa_deft.io.ros2.types import shared_types


NODE = Path(__file__).parent / "sut" / "ros2" / "sdk_node.py"
COUNT = 30
MUTATED = 5
TWIST_KEY = ("0/cmd_vel/geometry_msgs::msg::dds_::Twist_/"
             "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a")

SPEC = textwrap.dedent("""\
    name: sdk_pair
    modules:
      - name: listener
        command: ["{python}", "@NODE@", "listener", "--messages", "@MESSAGES@", "--out", "{run_dir}/listener.out",
                  "--expect", "@COUNT@"]
        env: @ENV@
        ready: {log: "listener: subscribed"}
      - name: talker
        command: ["{python}", "@NODE@", "talker", "--messages", "@MESSAGES@", "--out", "{run_dir}/talker.out",
                  "--count", "@COUNT@", "--rate", "40"]
        env: @ENV@
    channels:
      - {name: cmd_vel, topic: /cmd_vel, type: geometry_msgs/msg/Twist, encoding: cdr,
         producer: talker, consumers: [listener]}
    run:
      time_limit: 120
      end_when:
        - {module: listener, reason: every message arrived}
    """)
NO_NETWORK = '{http_proxy: "http://127.0.0.1:9", https_proxy: "http://127.0.0.1:9", ' \
             'HTTP_PROXY: "http://127.0.0.1:9", HTTPS_PROXY: "http://127.0.0.1:9", GIT_TERMINAL_PROMPT: "0"}'

POLICY = textwrap.dedent(f"""\
    <testcase id="ros2-linear-x" seed="1">
      <description>linear.x of the first {MUTATED} Twist messages set to -7.25</description>
      <policy id="reverse">
        <channel>cmd_vel</channel>
        <select limit="{MUTATED}"/>
        <set><field path="linear.x" value="-7.25"/></set>
      </policy>
    </testcase>
    """)


@pytest.fixture(scope="module")
def star_run(tmp_path_factory):
    """One star run with the policy: the first messages rewritten, the rest untouched; it ends when the listener
    has them all."""
    work = tmp_path_factory.mktemp("ros2_sdk")
    messages = work / "msgs"
    shared_types().write_definitions(["geometry_msgs/msg/Twist"], messages)
    spec = work / "spec.yaml"
    spec.write_text(SPEC.replace("@NODE@", str(NODE)).replace("@MESSAGES@", str(messages))
                    .replace("@COUNT@", str(COUNT)).replace("@ENV@", NO_NETWORK))
    policy = work / "tc.xml"
    policy.write_text(POLICY)
    run_dir, log = work / "run", work / "run.mcap"
    done = subprocess.run(
        [sys.executable, "-m", "astaa_deft.cli", "proxy", "--spec", str(spec), "--record", str(log),
         "--run-dir", str(run_dir), "--policy", str(policy)],
        capture_output=True, text=True, timeout=180)
    # The run ends when the listener has every message (however long a loaded machine takes to start the SDK's
    # nodes), not at a time after the launch.
    assert done.returncode in (0, 1), done.stderr
    assert "every message arrived" in done.stdout, done.stdout + done.stderr
    return run_dir, log


def _lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def test_the_talker_publishes_on_the_key_the_spec_derives(star_run):
    run_dir, _log = star_run
    sent = _lines(run_dir / "talker.out")
    assert len(sent) == COUNT
    # The SDK computed the type hash itself, from the local definitions.
    assert f"talker: publishing on {TWIST_KEY}" in (run_dir / "talker.log").read_text()


def test_untouched_messages_arrive_byte_identical_with_their_attachments(star_run):
    run_dir, _log = star_run
    sent = _lines(run_dir / "talker.out")
    got = _lines(run_dir / "listener.out.raw")
    assert len(got) == COUNT
    untouched_sent, untouched_got = sent[MUTATED:], got[MUTATED:]
    assert [m["payload"] for m in untouched_got] == [m["payload"] for m in untouched_sent]
    # The attachment (sequence, source timestamp, GID) is forwarded untouched on every message.
    assert [m["attachment"] for m in got] == [m["attachment"] for m in sent]
    first = parse_attachment(bytes.fromhex(got[0]["attachment"]))
    assert first is not None and len(first.gid) == 16
    assert [parse_attachment(bytes.fromhex(m["attachment"])).sequence for m in got] == list(range(COUNT))


def test_mutated_messages_decode_in_the_listener_with_exactly_linear_x_changed(star_run):
    run_dir, _log = star_run
    decoded = _lines(run_dir / "listener.out")
    assert len(decoded) == COUNT
    for i, message in enumerate(decoded):
        expected_x = -7.25 if i < MUTATED else 0.1 * i
        assert math.isclose(message["linear"][0], expected_x, abs_tol=1e-12)
        assert message["linear"][1:] == [0.0, 0.0] and message["angular"] == [0.0, 0.0, 0.5]
    sent = _lines(run_dir / "talker.out")
    got = _lines(run_dir / "listener.out.raw")
    codec = get_codec("cdr:geometry_msgs/msg/Twist")
    for i in range(MUTATED):
        before = codec.decode(bytes.fromhex(sent[i]["payload"]))
        after = codec.decode(bytes.fromhex(got[i]["payload"]))
        before["linear"]["x"] = -7.25
        assert after == before


def test_the_log_decodes_with_mcap_ros2_support(star_run):
    _run_dir, log = star_run
    seen: dict[str, int] = {}
    with open(log, "rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for schema, channel, _message in reader.iter_messages():
            if channel.message_encoding != "cdr":
                assert channel.message_encoding == "json"  # the tool's own channels stay JSON
                continue
            assert schema.encoding == "ros2msg" and schema.name == "geometry_msgs/msg/Twist"
            seen[channel.topic] = seen.get(channel.topic, 0) + 1
        stream.seek(0)
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        decoded = [(channel.topic, value)
                   for _s, channel, _m, value in reader.iter_decoded_messages(topics=sorted(seen))]
    assert seen.get(TWIST_KEY) == COUNT
    assert len(decoded) == sum(seen.values())
    delivered = [value for topic, value in decoded if topic == TWIST_KEY]
    assert [v.linear.x for v in delivered[:MUTATED]] == [-7.25] * MUTATED
    assert delivered[-1].linear.x == pytest.approx(0.1 * (COUNT - 1))
