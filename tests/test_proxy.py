"""The proxy end to end: real subprocess modules, real Zenoh on loopback, real MCAP.

The SUT is tests/sut: a talker and listeners that import nothing from
astaa-deft and find Zenoh only through zenoh.Config.from_env().
"""

from __future__ import annotations

import json
import re
import signal
import socket
import subprocess
import time
from pathlib import Path

import pytest

from astaa_deft.io.log.reader import read_log
from proxy_helpers import ECHO_SPEC, SUT_DIR, alive, proxy_cmd, received, run_proxy, started_pids


def test_sut_scripts_are_third_party_style():
    for script in ("talker.py", "listener.py"):
        text = (SUT_DIR / script).read_text()
        assert "astaa_deft" not in text and "Config.from_env()" in text


def test_star_delivers_byte_identical_records_and_isolates(tmp_path):
    run_dir, log = tmp_path / "run", tmp_path / "run.mcap"
    res = run_proxy(ECHO_SPEC, "--record", str(log), "--duration", "3", "--run-dir", str(run_dir),
                    "--param", "count=300", "--param", "garbage_every=25", "--param", "extra_key=test/extra")
    assert res.returncode == 0, res.stdout + res.stderr

    got = received(run_dir / "listener.out")
    data = [(p, a) for k, p, a in got if k == "test/data"]
    assert len(data) == 300
    # Payloads and attachments arrive exactly as sent, in order — garbage included.
    for i, (payload, att) in enumerate(data, start=1):
        assert bytes.fromhex(att) == f"seq={i}".encode()
        if i % 25 == 0:
            assert payload == b"\xff\x00not json" + bytes([i % 256])
        else:
            assert json.loads(payload)["header"]["seq"] == i
    # The outsider listens on the same key but is no declared consumer: star mode keeps it out.
    assert [k for k, _, _ in received(run_dir / "outsider.out") if k == "test/data"] == []

    contents = read_log(log)
    assert contents.finished and not contents.warnings
    logged = contents.on("test/data")
    assert [m.data for m in logged] == [p for p, _ in data]  # log count and bytes = what the consumer got
    flags = contents.flags()
    assert len(flags) == 300 // 25 and {f["channel"] for f in flags} == {"data"}
    assert all(f["kind"] == "undecodable" for f in flags)
    # The undeclared key is forwarded (catch-all), reported once, and logged.
    assert sum(1 for k, _, _ in got if k == "test/extra") == 300
    assert len(contents.events("undeclared_key")) == 1
    assert len(contents.on("test/extra")) == 300
    # The log is self-contained: spec attached, channel typed with a JSON schema.
    assert b"name: echo" in contents.attachments["spec.yaml"]
    assert contents.channels["test/data"].schema_name == "Sample"
    assert contents.channels["test/data"].metadata["producer"] == "talker"


def test_passive_mode_observes_without_routing(tmp_path):
    run_dir, log = tmp_path / "run", tmp_path / "run.mcap"
    res = run_proxy(ECHO_SPEC, "--passive", "--record", str(log), "--duration", "3", "--run-dir", str(run_dir),
                    "--param", "count=300")
    assert res.returncode == 0, res.stdout + res.stderr
    data = [p for k, p, _ in received(run_dir / "listener.out") if k == "test/data"]
    assert len(data) == 300
    # No star: the outsider hears the talker directly, as on the plain bus.
    assert len([k for k, _, _ in received(run_dir / "outsider.out") if k == "test/data"]) == 300
    contents = read_log(log)
    assert [m.data for m in contents.on("test/data")] == data
    configs = [json.loads(p.read_text()) for p in run_dir.glob("zenoh-*.json5")]
    assert configs and all("namespace" not in c and c["mode"] == "client" for c in configs)


def test_module_crash_is_an_event_others_keep_running_exit_1_no_orphans(tmp_path):
    run_dir, log = tmp_path / "run", tmp_path / "run.mcap"
    res = run_proxy(ECHO_SPEC, "--record", str(log), "--duration", "4", "--run-dir", str(run_dir),
                    "--param", "count=1000", "--param", "rate=100", "--param", "crash_after=50",
                    "--param", "spawn_child=--spawn-child")
    assert res.returncode == 1, res.stdout + res.stderr
    assert "module 'talker' exit code 3" in res.stdout
    assert "simulated crash" in res.stdout
    contents = read_log(log)
    exits = contents.events("process_exit")
    crash = [e for e in exits if e["module"] == "talker"]
    assert len(crash) == 1 and crash[0]["abnormal"] and crash[0]["returncode"] == 3
    # The others kept running until the end of the run: their exits came at shutdown.
    others = [e for e in exits if e["module"] != "talker"]
    assert {e["module"] for e in others} == {"listener", "outsider", "bystander"}
    assert all(e["during_shutdown"] for e in others)
    assert min(e["time_ns"] for e in others) - crash[0]["time_ns"] > 2e9
    # No orphans: every process we started is gone, the talker's own child too.
    pids = list(started_pids(run_dir).values())
    child = re.search(r"child pid (\d+)", (run_dir / "talker.log").read_text())
    assert child
    pids.append(int(child.group(1)))
    time.sleep(0.2)
    assert [p for p in pids if alive(p)] == []


def test_kill_9_of_proxy_keeps_the_log_readable(tmp_path):
    run_dir, log = tmp_path / "run", tmp_path / "run.mcap"
    proc = subprocess.Popen(proxy_cmd(ECHO_SPEC, "--record", str(log), "--run-dir", str(run_dir),
                                      "--param", "count=100000", "--param", "rate=1000",
                                      "--param", "spawn_child=--spawn-child"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and len(received(run_dir / "listener.out")) < 1500:
            time.sleep(0.1)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    pids = started_pids(run_dir)
    child = re.search(r"child pid (\d+)", (run_dir / "talker.log").read_text())
    assert child
    pids["talker's child"] = int(child.group(1))
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and any(alive(p) for p in pids.values()):
        time.sleep(0.1)
    assert [m for m, p in pids.items() if alive(p)] == [], "modules outlived a killed proxy"
    time.sleep(1.0)  # the recorder finishes the log on its parent-death signal
    delivered = {json.loads(p)["header"]["seq"] for k, p, _ in received(run_dir / "listener.out")
                 if k == "test/data"}
    contents = read_log(log)  # must not raise
    recorded = {json.loads(m.data)["header"]["seq"] for m in contents.on("test/data")}
    print(f"kill -9 of the proxy: {len(delivered)} delivered, {len(delivered & recorded)} of them in the log")
    assert len(delivered) >= 1500
    assert sorted(delivered - recorded) == []  # every message the consumer received is in the log


def test_unwritable_log_path_is_one_clear_error(tmp_path):
    res = run_proxy(ECHO_SPEC, "--record", str(tmp_path / "missing" / "x.mcap"), "--duration", "1",
                    "--run-dir", str(tmp_path / "run"))
    assert res.returncode == 2
    assert "Traceback" not in res.stderr
    assert "log path folder" in res.stderr and "does not exist" in res.stderr
    assert not (tmp_path / "run" / "processes.json").exists()  # nothing was started


def test_port_in_use_is_one_clear_error(tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        spec = tmp_path / "sut.yaml"
        spec.write_text(ECHO_SPEC.read_text().replace("name: echo\n", f"name: echo\nzenoh:\n  endpoints: [\"tcp/127.0.0.1:{port}\"]\n")
                        .replace("{spec_dir}", str(SUT_DIR)))
        res = run_proxy(spec, "--duration", "1", "--run-dir", str(tmp_path / "run"))
    assert res.returncode == 2, res.stdout + res.stderr
    assert "Traceback" not in res.stderr
    assert f"127.0.0.1:{port}" in res.stderr and "port may be in use" in res.stderr
    assert not (tmp_path / "run" / "processes.json").exists()


def test_missing_module_command_is_one_clear_error_and_stops_the_others(tmp_path):
    spec = tmp_path / "sut.yaml"
    spec.write_text(ECHO_SPEC.read_text().replace('command: ["{python}", "-c", "import time; time.sleep(600)"]',
                                                  'command: ["no-such-program-xyz"]')
                    .replace("{spec_dir}", str(SUT_DIR)))
    run_dir = tmp_path / "run"
    res = run_proxy(spec, "--duration", "5", "--run-dir", str(run_dir))
    assert res.returncode == 2, res.stdout + res.stderr
    assert "Traceback" not in res.stderr
    assert "module 'bystander': command 'no-such-program-xyz' not found" in res.stderr
    pids = started_pids(run_dir)
    assert set(pids) == {"listener", "outsider", "talker"}
    assert [m for m, p in pids.items() if alive(p)] == []


def test_router_configs_do_not_wait_to_scout():
    """Scouting is off, so a router must not spend scouting.delay (500 ms by default) at open."""
    from astaa_deft.engine.bus import zenoh_config as zc

    router = zc.config_dict(mode="router", listen=[zc.loopback_endpoint()])
    assert router["scouting"]["delay"] == 0 and router["scouting"]["multicast"]["enabled"] is False
    assert "delay" not in zc.config_dict(mode="client", connect=["tcp/127.0.0.1:7447"])["scouting"]
    assert "delay" not in zc.config_dict(mode="router", gossip=True)["scouting"]  # gossip may find peers


# ---------------------------------------------------------------- bursts (in process, real Zenoh on loopback)

def _wait_until(condition, limit: float = 30.0) -> None:
    """Poll until ``condition()`` holds (bounded, so a failure ends the test instead of hanging it)."""
    deadline = time.monotonic() + limit
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.01)


def test_bursts_hand_over_every_queued_sample_once_in_order_even_as_the_subscriber_closes():
    import zenoh

    from astaa_deft.engine.bus import zenoh_config as zc
    from astaa_deft.engine.bus.proxy import BURST_LIMIT, run_bursts

    session = zc.open_session(zc.config_dict(mode="peer", listen=[zc.loopback_endpoint()]))
    try:
        sub = session.declare_subscriber("burst/k", zenoh.handlers.FifoChannel(1000))
        pub = session.declare_publisher("burst/k")
        count = 3 * BURST_LIMIT + 4  # the last burst is cut short by the closed subscriber
        for i in range(count):
            pub.put(str(i))
        _wait_until(lambda: False, 0.3)  # local delivery is immediate; a moment for the FIFO anyway
        fifo = sub.handler
        sub.undeclare()  # what is queued stays readable; then try_recv raises
        bursts: list[list[int]] = []
        idle: list[bool] = []
        with pytest.raises(zenoh.ZError):
            run_bursts(fifo, lambda samples: bursts.append([int(s.payload.to_string()) for s in samples]),
                       lambda: idle.append(True))
    finally:
        session.close()
    assert [i for burst in bursts for i in burst] == list(range(count))
    assert [len(b) for b in bursts] == [BURST_LIMIT, BURST_LIMIT, BURST_LIMIT, 4]
    assert not idle  # never ran empty before it closed


def test_intercepted_bursts_deliver_each_message_once_in_order_and_send_the_recorder_each_row_once():
    """set on every message through the star proxy, under a burst: the consumer gets each mutated message
    once and in order, and the rows the proxy sends the recorder hold each delivery once, in order, with its
    original (the log written from them: the next test)."""
    import zenoh

    from astaa_deft.engine.bus import zenoh_config as zc
    from astaa_deft.engine.bus.interception import InterceptionBridge
    from astaa_deft.engine.bus.proxy import BURST_LIMIT, StarProxy
    from astaa_deft.engine.bus.topology import intercepted_key, unpack_deliveries, wire_event_parts
    from astaa_deft.engine.intercept import Interceptor, load_dictionary, parse_testcase
    from astaa_deft.engine.spec.loader import load_spec_text

    spec = load_spec_text("""
name: bursts
modules: [{name: src, command: "true"}, {name: dst, command: "true"}]
channels:
  - {name: data, key: b/data, producer: src, consumers: [dst], type: Msg}
types:
  Msg: {seq: uint64, value: float64}
""")
    testcase = parse_testcase(b'<testcase id="t" seed="1"><description/><policy id="p"><channel>data</channel>'
                              b'<set><field path="value" value="-1.0"/></set></policy></testcase>', "t.xml", spec)
    endpoint = zc.loopback_endpoint()
    tool = zc.open_session(zc.config_dict(mode="router", listen=[endpoint]))
    client = zc.open_session(zc.config_dict(mode="client", connect=[endpoint]))
    count = 10 * BURST_LIMIT + 7
    delivered: list[bytes] = []
    rows: list[tuple] = []
    try:
        bridge = InterceptionBridge(tool, Interceptor(testcase, spec, load_dictionary()), time.monotonic())
        proxy = StarProxy(tool, spec, make_forwarder=bridge.make_forwarder)
        proxy.start()
        bridge.start()
        subs = [client.declare_subscriber("sut/dst/b/data", lambda s: delivered.append(s.payload.to_bytes())),
                client.declare_subscriber(intercepted_key("b/data"),
                                          lambda s: rows.extend(unpack_deliveries(s.payload.to_bytes())))]
        _wait_until(lambda: False, 0.5)  # the router learns of the subscribers
        pub = client.declare_publisher("sut/src/b/data", congestion_control=zenoh.CongestionControl.BLOCK)
        for i in range(count):  # as fast as it goes: the forwarder's FIFO fills and it drains it in bursts
            pub.put(json.dumps({"seq": i, "value": 0.5}))
        _wait_until(lambda: len(delivered) >= count and len(rows) >= count)
        proxy.stop()
        bridge.stop()
        for sub in subs:
            sub.undeclare()
    finally:
        client.close()
        tool.close()
    assert [json.loads(p) for p in delivered] == [{"seq": i, "value": -1.0} for i in range(count)]
    assert [json.loads(original) for _, _, original, _, _ in rows] == [{"seq": i, "value": 0.5} for i in range(count)]
    assert [payload for _, payload, _, _, _ in rows] == delivered
    assert all(was_delivered for _, _, _, was_delivered, _ in rows)
    assert [wire_event_parts(event)["message_index"] for *_, event in rows] == list(range(1, count + 1))
    times = [t for t, *_ in rows]
    assert times == sorted(times)


def test_intercepted_bursts_are_in_the_log_each_delivery_once_in_order_with_its_original(tmp_path):
    """The same through the tool and its recorder: a talker publishing as fast as it can, `set` on every
    message; the log holds exactly what the listener received, in its order, each delivery once with its
    original and its mutation event."""
    count = 3000
    policy = tmp_path / "set.xml"
    policy.write_text('<testcase id="t" seed="1"><description/><policy id="p"><channel>data</channel>'
                      '<set><field path="value" value="-1.0"/></set></policy></testcase>')
    run_dir, log_path = tmp_path / "run", tmp_path / "run.mcap"
    res = run_proxy(ECHO_SPEC, "--policy", str(policy), "--record", str(log_path), "--duration", "6",
                    "--run-dir", str(run_dir), "--param", f"count={count}", "--param", "rate=1000000")
    assert res.returncode == 0, res.stdout + res.stderr
    got = [p for k, p, _ in received(run_dir / "listener.out") if k == "test/data"]
    assert [json.loads(p)["header"]["seq"] for p in got] == list(range(1, count + 1))
    assert {json.loads(p)["value"] for p in got} == {-1.0}
    log = read_log(log_path)
    assert log.finished and not log.damage
    delivered = log.on("test/data")
    assert [bytes(m.data) for m in delivered] == got  # the log holds what the listener received, in its order
    originals = [json.loads(m.data) for m in log.on("/astaa/original/test/data")]
    assert [(o["header"]["seq"], o["value"]) for o in originals] == [(i, i * 0.5) for i in range(1, count + 1)]
    mutations = [json.loads(m.data) for m in log.on("/astaa/mutations")]
    assert [(m["original_sequence"], m["delivered_sequence"]) for m in mutations] == [
        (i, i) for i in range(1, count + 1)]
    times = [m.log_time for m in delivered]
    assert times == sorted(times)
