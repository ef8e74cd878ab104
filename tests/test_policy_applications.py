"""A policy whose window closed without touching a message is named, with why.

Before: a run said only "mutations applied: 0" — not which policy touched
nothing, nor that the SUT had started after the window closed.
"""

from __future__ import annotations

from astaa_deft.engine.intercept.applications import ChannelTraffic, PolicyApplications, untouched_reason
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.session.summary import format_info
from proxy_helpers import ECHO_SPEC, run_proxy


def app(**kw) -> PolicyApplications:
    base = dict(testcase="t", policy="p", action="set", window_start_s=5.0, window_end_s=7.0, anchor=None,
                in_window=0, touched=0, traffic=(ChannelTraffic("data", 10, 20.0, 25.0),), run_end_s=30.0)
    base.update(kw)
    return PolicyApplications(**base)  # type: ignore[arg-type]


def test_reasons_point_at_what_the_traffic_shows():
    assert untouched_reason(app(touched=3)) is None
    late = untouched_reason(app())
    assert "first message on 'data' came at 20.0 s, after the window had closed" in late and "started late" in late
    silent = untouched_reason(app(traffic=(ChannelTraffic("data", 0, None, None),)))
    assert "carried no message in the whole run" in silent
    gone = untouched_reason(app(traffic=(ChannelTraffic("data", 5, 1.0, 2.0),)))
    assert "fell silent at 2.0 s, before the window opened" in gone
    never = untouched_reason(app(window_start_s=None, window_end_s=None, anchor="message 3 on channel 'x'"))
    assert "never opened" in never and "message 3 on channel 'x'" in never
    early_end = untouched_reason(app(run_end_s=3.0))
    assert "before its window [5 s, 7 s) opened" in early_end
    unselected = untouched_reason(app(in_window=4, traffic=(ChannelTraffic("data", 10, 4.0, 8.0),)))
    assert "4 message(s) arrived in its window" in unselected


def test_live_run_names_the_idle_policy_on_the_terminal_and_in_the_log(tmp_path):
    # The talker publishes for half a second after a 0.5 s start delay, then idles: policy 'late' waits for
    # a window after its last message (anchored on it: no guess at start-up time on a loaded machine),
    # 'early' closes before the first message, 'hits' touches messages.
    policy = tmp_path / "tc.xml"
    policy.write_text("""<?xml version="1.0" encoding="UTF-8"?>
<testcase id="windows" seed="1">
  <description>two windows that see nothing</description>
  <policy id="early"><channel>data</channel><window from="0" to="0.05"/><drop/></policy>
  <policy id="late"><channel>data</channel>
    <window from="0.5" to="1"><after channel="data" message="100"/></window><drop/></policy>
  <policy id="hits"><channel>data</channel><select every="50"/><drop/></policy>
</testcase>
""")
    log = tmp_path / "run.mcap"
    res = run_proxy(ECHO_SPEC, "--policy", str(policy), "--record", str(log), "--duration", "6",
                    "--run-dir", str(tmp_path / "run"), "--param", "count=100", "--param", "rate=200")
    assert res.returncode in (0, 1), res.stdout + res.stderr
    out = res.stdout
    assert "policy 'early' (drop) touched no message: no message arrived in its window [0 s, 0.05 s)" in out
    assert "after the window had closed" in out
    assert "policy 'late' (drop) touched no message" in out and "fell silent at" in out
    assert "policy 'hits'" not in out  # it touched messages: nothing to explain
    records = [r for r in (rec.decode(e) for e in read_log(log).events())
               if isinstance(r, rec.PolicyApplicationsRecord)]
    by_id = {r.policy: r for r in records}
    assert set(by_id) == {"early", "late", "hits"}
    assert by_id["hits"].touched == 2 and by_id["hits"].untouched_reason is None
    assert by_id["early"].touched == 0 and "after the window had closed" in (by_id["early"].untouched_reason or "")
    late = by_id["late"]
    assert late.anchor == "message 100 on channel 'data'" and late.touched == 0
    assert late.window_start_s is not None and late.window_end_s is not None
    assert abs(late.window_end_s - late.window_start_s - 0.5) < 1e-9
    info = format_info(read_log(log))
    assert "policies: early 0 touched, late 0 touched, hits 2 touched" in info
    assert "policy 'late' (drop) touched no message" in info
