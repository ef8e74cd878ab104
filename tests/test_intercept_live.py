"""Each fault action on live Zenoh traffic between real processes: what the
consumer actually received, and what the log holds (original, delivered,
mutation event). The SUT is tests/sut (third-party-style talker → listener)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from astaa_deft.io.log.reader import read_log
from proxy_helpers import ECHO_SPEC, received, run_proxy

COUNT = 200


def write_testcase(tmp_path: Path, policy_body: str, select: str = "") -> Path:
    path = tmp_path / "tc.xml"
    path.write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<testcase id="live" seed="3">
  <description>live action test</description>
  <policy id="p1">
    <channel>data</channel>
    {select}
    {policy_body}
  </policy>
</testcase>
""")
    return path


def run_with(tmp_path: Path, policy: Path):
    run_dir, log = tmp_path / "run", tmp_path / "run.mcap"
    res = run_proxy(ECHO_SPEC, "--policy", str(policy), "--record", str(log), "--duration", "3",
                    "--run-dir", str(run_dir), "--param", f"count={COUNT}", "--param", "rate=200")
    assert res.returncode in (0, 1), res.stdout + res.stderr
    got = [_json_or_bytes(p) for k, p, _ in received(run_dir / "listener.out") if k == "test/data"]
    contents = read_log(log)
    mutations = [json.loads(m.data) for m in contents.on("/astaa/mutations")]
    return got, contents, mutations, res


def _json_or_bytes(payload: bytes):
    try:
        return json.loads(payload)
    except ValueError:
        return payload


def seqs(messages):
    return [m["header"]["seq"] for m in messages if isinstance(m, dict)]


def test_set_nan_reaches_the_consumer_and_is_logged_three_ways(tmp_path):
    got, log, mutations, _ = run_with(tmp_path, write_testcase(
        tmp_path, '<set><field path="value" value="dict:float.nan"/></set>', '<select every="5"/>'))
    assert len(got) == COUNT
    nan = [m for m in got if math.isnan(m["value"])]
    assert seqs(nan) == list(range(1, COUNT + 1, 5))  # every 5th from the first
    assert all(m["value"] == m["header"]["seq"] * 0.5 for m in got if m not in nan)
    assert len(mutations) == len(nan)
    first = mutations[0]
    assert first["action"] == "set" and first["channel"] == "data" and first["consumers"] == ["listener"]
    assert first["fields"][0]["path"] == "value" and first["fields"][0]["new"] == {"float": "nan"}
    # Original and delivered, cross-referenced by the event.
    originals = log.on("/astaa/original/test/data")
    delivered = log.on("test/data")
    assert len(originals) == len(nan) and len(delivered) == COUNT
    orig = json.loads(originals[first["original_sequence"] - 1].data)
    dlv = json.loads(delivered[first["delivered_sequence"] - 1].data)
    assert orig["value"] == 0.5 and math.isnan(dlv["value"]) and orig["header"] == dlv["header"]


def test_drop(tmp_path):
    got, log, mutations, _ = run_with(tmp_path, write_testcase(tmp_path, "<drop/>", '<select every="10"/>'))
    assert seqs(got) == [i for i in range(1, COUNT + 1) if i % 10 != 1]
    assert len(mutations) == COUNT // 10 and all(m["delivered_sequence"] is None for m in mutations)
    assert len(log.on("test/data")) == COUNT - COUNT // 10  # the log holds what was delivered


def test_delay(tmp_path):
    got, log, mutations, _ = run_with(tmp_path, write_testcase(tmp_path, '<delay ms="100"/>', '<select every="50"/>'))
    order = seqs(got)
    assert sorted(order) == list(range(1, COUNT + 1))  # nothing lost
    assert {m["detail"].get("delay_ms") for m in mutations} == {100}
    # The consumer got the messages in the order the proxy delivered them (the log's order).
    delivered = [json.loads(m.data) for m in log.on("test/data")]
    assert [m["header"]["seq"] for m in delivered] == order
    delivered_at = {m["header"]["seq"]: t.log_time / 1e9 for m, t in zip(delivered, log.on("test/data"), strict=True)}
    stamp = {m["header"]["seq"]: m["header"]["stamp"] for m in delivered}  # the talker's publish time
    # Each delayed message is held for its 100 ms (at 200 Hz about 20 later messages overtake it on a quiet
    # machine; how many depends on how fast the talker really published, so the count is taken from this
    # run): the messages that overtook it are the later ones delivered while it was held, and there are some.
    for delayed in (1, 51, 101, 151):
        held = delivered_at[delayed] - stamp[delayed]
        assert 0.1 <= held < 5.0, (delayed, held)  # 5 s: a hang, not a delay
        overtaken_by = [seq for seq in order[:order.index(delayed)] if seq > delayed]
        assert len(overtaken_by) == order.index(delayed) - (delayed - 1)  # none of the earlier ones came after
        assert overtaken_by and all(stamp[delayed] < stamp[seq] < delivered_at[delayed] for seq in overtaken_by)
        print(f"message {delayed}: held {held * 1e3:.0f} ms, overtaken by {len(overtaken_by)}")


def test_duplicate(tmp_path):
    got, _, mutations, _ = run_with(tmp_path, write_testcase(tmp_path, '<duplicate copies="2"/>', '<select every="20"/>'))
    order = seqs(got)
    assert len(order) == COUNT + 2 * (COUNT // 20)
    assert order.count(21) == 3 and order.count(22) == 1


def test_reorder(tmp_path):
    got, _, _, _ = run_with(tmp_path, write_testcase(tmp_path, "<reorder/>", '<select every="2"/>'))
    order = seqs(got)
    assert sorted(order) == list(range(1, COUNT + 1))
    assert order[:6] == [2, 1, 4, 3, 6, 5]


def test_interleave(tmp_path):
    got, _, mutations, _ = run_with(tmp_path, write_testcase(
        tmp_path, '<interleave rate="50"><field path="value" value="dict:float.inf"/></interleave>'))
    injected = [m for m in got if math.isinf(m["value"])]
    real = [m for m in got if not math.isinf(m["value"])]
    assert seqs(real) == list(range(1, COUNT + 1))  # real messages pass untouched
    # 1 s of traffic at 50 Hz of injections (the window is the whole run).
    assert 25 <= len(injected) <= 150, len(injected)
    assert all(m["action"] == "interleave" for m in mutations)


def test_corrupt_forwards_undecodable_bytes(tmp_path):
    got, log, mutations, _ = run_with(tmp_path, write_testcase(
        tmp_path, '<corrupt mode="truncate" keep="0.5"/>', '<select every="40"/>'))
    assert len(got) == COUNT
    assert len(mutations) == COUNT // 40
    originals = [m.data for m in log.on("/astaa/original/test/data")]
    truncated = []
    for m, orig in zip(mutations, originals):
        data = log.on("test/data")[m["delivered_sequence"] - 1].data
        assert data == orig[: len(data)] and len(data) < len(orig)
        truncated.append(data)
    # The consumer received exactly the truncated bytes (not JSON any more), in place of the originals.
    assert [p for p in got if isinstance(p, bytes)] == truncated


@pytest.mark.parametrize("bad", ["<nope/>", '<set><field path="valu" value="1"/></set>'])
def test_bad_policy_is_exit_2_before_anything_starts(tmp_path, bad):
    res = run_proxy(ECHO_SPEC, "--policy", str(write_testcase(tmp_path, bad)), "--duration", "1",
                    "--run-dir", str(tmp_path / "run"))
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert "tc.xml:" in res.stderr
    assert not (tmp_path / "run" / "processes.json").exists()
