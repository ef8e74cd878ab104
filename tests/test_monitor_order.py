"""Online and offline monitors judge one run in one order: message time, then spec channel order, then sequence.

Receive times differ between the tool's subscriber and the recorder's by
scheduling noise; judged in receive order, the two named different first
findings for one run. Both now use the message's
own Zenoh timestamp (the router stamps it once; the proxy forwards it).
"""

from __future__ import annotations

import threading
import time

from astaa_deft.engine.bus import zenoh_config as zc
from astaa_deft.engine.monitor import check_log
from astaa_deft.engine.monitor.online import OnlineMonitors
from astaa_deft.engine.monitor.order import REORDER_WINDOW_NS

from monitor_helpers import HandMadeLog, command, load, ns

INVARIANTS = """
- {name: accel_cmd, kind: bound, channel: command, field: acceleration, max: 4}
- {name: pose_speed, kind: bound, channel: localization, field: speed, max: 30}
"""


def test_offline_follows_message_time_not_the_recorders_receive_time(tmp_path):
    spec = load(INVARIANTS)
    log = HandMadeLog(tmp_path / "run.mcap", spec)
    # The command was published first (1.00 s) but reached the recorder after the pose (1.20 s vs 1.10 s).
    log.message("localization", 1.10, {"header": {"seq": 1, "stamp": 1.1}, "x": 0.0, "y": 0.0, "heading": 0.0,
                                       "speed": 99.0}, published=1.05)
    log.message("command", 1.20, command(1, acceleration=50.0), published=1.00)
    log.event("run_end", 2.0, reason="time limit")
    result = check_log(log.close(), spec)
    assert [v.invariant for v in result.violations] == ["accel_cmd", "pose_speed"]
    assert result.verdict.first.invariant == "accel_cmd"
    assert result.verdict.first.time_ns == ns(1.00)


def test_online_waits_for_a_late_earlier_message_and_judges_it_first():
    spec = load(INVARIANTS)
    session = zc.open_session(zc.config_dict(mode="peer", listen=[zc.loopback_endpoint()]))
    found = []
    lock = threading.Lock()

    def on_violation(v):
        with lock:
            found.append(v)

    try:
        monitors = OnlineMonitors(spec, time.time_ns(), on_violation)
        monitors.subscribe(session, [("av/cmd", "command"), ("av/loc", "localization")])
        early = session.new_timestamp()  # the command's own time: before the pose's
        time.sleep(0.002)
        late = session.new_timestamp()
        pose = b'{"header": {"seq": 1, "stamp": 0.0}, "x": 0, "y": 0, "heading": 0, "speed": 99.0}'
        session.put("av/loc", pose, timestamp=late)
        time.sleep(REORDER_WINDOW_NS / 1e9 / 4)  # arrives later, still inside the reorder window
        session.put("av/cmd", b'{"header": {"seq": 1, "stamp": 0.0}, "acceleration": 50.0, "steering": 0.0}',
                    timestamp=early)
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline:
            with lock:
                if len(found) == 2:
                    break
            time.sleep(0.02)
        verdict = monitors.finish(time.time_ns())
    finally:
        session.close()
    assert [v.invariant for v in found] == ["accel_cmd", "pose_speed"]
    assert verdict.first.invariant == "accel_cmd"
