"""The ROS 2 graph and services across the star, seen by zenoh-ros2-sdk nodes (a client no one here wrote).

Real subprocesses on loopback. In the star every module has a Zenoh
namespace of its own, so an rmw_zenoh node's liveliness tokens
(``@ros2_lv/...``) and service queryables would stay in it; the proxy mirrors
them into the namespaces the spec wires. The SDK gets message definitions
locally (service definitions inline) and a proxy on 127.0.0.1:9, so nothing
leaves the machine.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
import zenoh_ros2_sdk  # noqa: F401  -- in the test extra; the ROS 2 client these tests run (missing: fail, not skip)
import zenoh

from astaa_deft.engine.bus import zenoh_config as zc
from astaa_deft.engine.bus.star_requests import StarLiveliness, ros2_token_destinations
from astaa_deft.io.ros2.tokens import parse_token
from astaa_deft.io.ros2.types import shared_types
from astaa_deft.engine.spec.loader import load_spec


NODE = Path(__file__).parent / "sut" / "ros2" / "sdk_node.py"
NO_NETWORK = '{http_proxy: "http://127.0.0.1:9", https_proxy: "http://127.0.0.1:9", ' \
             'HTTP_PROXY: "http://127.0.0.1:9", HTTPS_PROXY: "http://127.0.0.1:9", GIT_TERMINAL_PROMPT: "0"}'
TWIST_KEY = ("0/cmd_vel/geometry_msgs::msg::dds_::Twist_/"
             "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a")
CALLS = 4

# talker → listener on /cmd_vel; asker calls the adder's /add_two_ints (a key no channel declares: the catch-all).
SPEC = textwrap.dedent("""\
    name: sdk_graph
    modules:
      - name: listener
        command: ["{python}", "@NODE@", "listener", "--graph", "--messages", "@MESSAGES@",
                  "--out", "{run_dir}/listener.out"]
        env: @ENV@
        ready: {log: "listener: subscribed"}
      - name: talker
        command: ["{python}", "@NODE@", "talker", "--messages", "@MESSAGES@", "--out", "{run_dir}/talker.out",
                  "--count", "20", "--rate", "20", "--node", "@TALKER@"]
        env: @ENV@
      - name: adder
        command: ["{python}", "@NODE@", "server", "--messages", "@MESSAGES@", "--out", "{run_dir}/adder.out"]
        env: @ENV@
        ready: {log: "server: serving"}
      - name: asker
        command: ["{python}", "@NODE@", "client", "--messages", "@MESSAGES@", "--out", "{run_dir}/asker.out",
                  "--count", "@CALLS@"]
        env: @ENV@
    channels:
      - {name: cmd_vel, topic: /cmd_vel, type: geometry_msgs/msg/Twist, encoding: cdr,
         producer: talker, consumers: [listener]}
    """)


def _write_spec(work: Path, talker_node: str) -> Path:
    messages = work / "msgs"
    if not messages.exists():
        shared_types().write_definitions(["geometry_msgs/msg/Twist"], messages)
    spec = work / f"spec-{talker_node}.yaml"
    spec.write_text(SPEC.replace("@NODE@", str(NODE)).replace("@MESSAGES@", str(messages))
                    .replace("@ENV@", NO_NETWORK).replace("@TALKER@", talker_node).replace("@CALLS@", str(CALLS)))
    return spec


def _start(spec: Path, run_dir: Path, seconds: float) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "astaa_deft.cli", "proxy", "--spec", str(spec), "--run-dir", str(run_dir),
         "--duration", str(seconds)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    """Two star runs of the same system at once (as two campaign cases), their talker nodes named apart."""
    work = tmp_path_factory.mktemp("ros2_graph")
    runs = {name: (_write_spec(work, name), work / name) for name in ("talker_a", "talker_b")}
    procs = {name: _start(spec, run_dir, 8) for name, (spec, run_dir) in runs.items()}
    for name, proc in procs.items():
        _out, err = proc.communicate(timeout=120)
        assert proc.returncode in (0, 1), f"{name}: {err}"
    return {name: run_dir for name, (_spec, run_dir) in runs.items()}


def _zid(run_dir: Path, module: str) -> str:
    return (run_dir / f"{module}.out.zid").read_text().strip()


def test_token_parsing_and_wiring_follow_the_data_keys(tmp_path):
    spec = load_spec(_write_spec(tmp_path, "teleop"))
    zid = "0123456789abcdef0123456789abcdef"
    endpoint = f"{TWIST_KEY.split('/', 2)[2]}/::,7:,:,:,,"
    publisher = parse_token(f"@ros2_lv/0/{zid}/0/1/MP/%/%/teleop/%cmd_vel/{endpoint}")
    subscription = parse_token(f"@ros2_lv/0/{zid}/0/3/MS/%/%/listener/%cmd_vel/{endpoint}")
    node = parse_token(f"@ros2_lv/0/{zid}/0/0/NN/%/%/teleop")
    assert publisher is not None and subscription is not None and node is not None
    assert publisher.kind == "MP" and publisher.data_key == TWIST_KEY
    assert subscription.kind == "MS" and subscription.data_key == TWIST_KEY
    assert node.kind == "NN" and node.data_key is None
    assert ros2_token_destinations(spec, "talker", publisher) == ("listener",)
    assert ros2_token_destinations(spec, "listener", publisher) == ()  # not its producer
    assert ros2_token_destinations(spec, "listener", subscription) == ("talker",)
    assert set(ros2_token_destinations(spec, "talker", node)) == {"listener", "adder", "asker"}
    service = parse_token(f"@ros2_lv/0/{zid}/0/2/SS/%/%/adder/%add_two_ints/"
                          "example_interfaces::srv::dds_::AddTwoInts_/RIHS01_ab/::,10:,:,:,,")
    assert service is not None and service.kind == "SS"
    assert service.data_key == "0/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/RIHS01_ab"
    assert set(ros2_token_destinations(spec, "adder", service)) == {"listener", "talker", "asker"}  # catch-all
    assert parse_token("@ros2_lv/0/x/0/0/XX/%/%/n") is None
    assert parse_token("@ros2_lv/zero/x/0/0/NN/%/%/n") is None
    assert parse_token(f"@ros2_lv/0/{zid}/0/1/MP/%/%/teleop/%/{endpoint}") is None  # an endpoint without a name
    assert parse_token("node/planner/alive") is None


def test_the_listener_sees_the_talker_in_its_graph_through_the_star(two_runs):
    run_dir = two_runs["talker_a"]
    graph = _lines(run_dir / "listener.out.graph")
    assert graph, (run_dir / "listener.log").read_text()
    # The SDK's own graph API (ros2 topic info -v) names the talker's node as the publisher, itself as subscriber
    # (its own tokens it may list twice: the session's and the router's answer; Zenoh's doing, star or not).
    assert any(g["publishers"] == ["talker_a"] and set(g["subscribers"]) == {"base"} for g in graph)
    # A raw liveliness get returns the talker's tokens exactly as the talker declared them (its zid in the key).
    zid = _zid(run_dir, "talker")
    tokens = {t for g in graph for t in g["tokens"]}
    assert any(t.startswith(f"@ros2_lv/0/{zid}/") and "/NN/" in t and t.endswith("/talker_a") for t in tokens)
    assert any(t.startswith(f"@ros2_lv/0/{zid}/") and "/MP/" in t and "/%cmd_vel/" in t for t in tokens)
    # The node token reaches every module; the server's service token reaches the listener (catch-all).
    assert any("/SS/" in t and "/%add_two_ints/" in t for t in tokens)


def test_two_concurrent_star_runs_never_see_each_others_tokens(two_runs):
    for own, other in (("talker_a", "talker_b"), ("talker_b", "talker_a")):
        run_dir = two_runs[own]
        tokens = {t for g in _lines(run_dir / "listener.out.graph") for t in g["tokens"]}
        assert any(t.endswith(f"/{own}") for t in tokens)  # its own run's talker is seen …
        foreign = (_zid(two_runs[other], "talker"), _zid(two_runs[other], "adder"))
        assert not any(z in t for t in tokens for z in foreign)  # … the other run's nodes never
        assert not any(other in t for t in tokens)
        publishers = {p for g in _lines(run_dir / "listener.out.graph") for p in g["publishers"]}
        assert publishers == {own}


def test_a_ros2_service_is_called_through_the_star(two_runs):
    for run_dir in two_runs.values():
        assert "client: service seen" in (run_dir / "asker.log").read_text()
        answers = _lines(run_dir / "asker.out")
        assert answers == [{"a": i, "sum": i + 100} for i in range(CALLS)], (run_dir / "asker.log").read_text()
        assert _lines(run_dir / "adder.out") == [{"a": i, "b": 100} for i in range(CALLS)]


PAIR_SPEC = textwrap.dedent("""\
    name: sdk_other_definition
    modules:
      - name: listener
        command: ["{python}", "@NODE@", "listener", "--messages", "@MESSAGES@", "--out", "{run_dir}/listener.out"]
        env: @ENV@
      - name: talker
        command: ["{python}", "@NODE@", "talker", "--messages", "@OTHER@", "--out", "{run_dir}/talker.out",
                  "--count", "10", "--rate", "20"]
        env: @ENV@
    channels:
      - {name: cmd_vel, topic: /cmd_vel, type: geometry_msgs/msg/Twist, encoding: cdr,
         producer: talker, consumers: [listener]}
    """)


def test_a_node_with_another_definition_of_its_type_is_one_clear_line(tmp_path):
    """Hash mismatch at run time: the talker's Twist is defined otherwise (fields reordered: another RIHS01)."""
    messages, other = tmp_path / "msgs", tmp_path / "other_msgs"
    for directory in (messages, other):
        shared_types().write_definitions(["geometry_msgs/msg/Twist"], directory)
    twist = other / "geometry_msgs" / "msg" / "Twist.msg"
    fields = [line for line in twist.read_text().splitlines() if line.strip() and not line.startswith("#")]
    twist.write_text("\n".join(reversed(fields)) + "\n")
    spec = tmp_path / "spec.yaml"
    spec.write_text(PAIR_SPEC.replace("@NODE@", str(NODE)).replace("@MESSAGES@", str(messages))
                    .replace("@OTHER@", str(other)).replace("@ENV@", NO_NETWORK))
    done = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "proxy", "--spec", str(spec), "--run-dir",
                           str(tmp_path / "run"), "--duration", "4"], capture_output=True, text=True, timeout=120)
    assert "Traceback" not in done.stdout + done.stderr
    lines = [line for line in done.stdout.splitlines() if "type hash differs from channel 'cmd_vel'" in line]
    assert len(lines) == 1, done.stdout
    assert lines[0].startswith("-- undeclared key '0/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_")
    assert "from 'talker'" in lines[0] and "give the channel this key, or fix the definition" in lines[0]


def test_a_withdrawn_server_token_takes_its_mirrors_and_its_queryable_with_it(tmp_path):
    """In-process, real Zenoh on loopback: the proxy's session (a router) and two namespaced module clients."""
    spec = load_spec(_write_spec(tmp_path, "teleop"))
    endpoint = zc.loopback_endpoint()
    proxy = zc.open_session(zc.config_dict(mode="router", listen=[endpoint]))
    adder = zc.open_session(zc.config_dict(mode="client", connect=[endpoint], namespace="sut/adder"))
    asker = zc.open_session(zc.config_dict(mode="client", connect=[endpoint], namespace="sut/asker"))
    star = StarLiveliness(proxy, spec)
    star.start()
    service_key = "0/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/RIHS01_ab"
    token_key = f"@ros2_lv/0/{'ab' * 16}/0/3/SS/%/%/adder/%add_two_ints/{service_key.split('/', 2)[2]}/::,10:,:,:,,"

    def seen_by_asker() -> list[str]:
        return [str(r.ok.key_expr) for r in asker.liveliness().get("@ros2_lv/0/**", timeout=1.0) if r.ok is not None]

    def answers() -> list[bytes]:
        return [r.ok.payload.to_bytes() for r in asker.get(service_key, target=zenoh.QueryTarget.ALL_COMPLETE,
                                                          timeout=2.0) if r.ok is not None]

    queryable = adder.declare_queryable(service_key, lambda q: q.reply(service_key, b"sum"), complete=True)
    try:
        token = adder.liveliness().declare_token(token_key)
        deadline = time.monotonic() + 5
        while token_key not in seen_by_asker() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert seen_by_asker() == [token_key]
        assert answers() == [b"sum"]  # through the complete queryable mirrored into the asker's namespace
        token.undeclare()
        deadline = time.monotonic() + 5
        while seen_by_asker() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert seen_by_asker() == []
        assert answers() == []  # the mirrored queryable went with the token
    finally:
        star.stop()
        queryable.undeclare()
        for session in (asker, adder, proxy):
            session.close()
