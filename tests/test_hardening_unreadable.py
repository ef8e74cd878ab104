"""A message a monitor cannot read is never skipped in silence.

A localization message nested 100,000 deep does not decode: the collision monitor cannot place the ego for
it, so `check` of that run withholds its Pass (exit 3, naming the invariant and the count) instead of calling
604 of 605 messages a clean run. Monitors that judge such a message themselves keep doing so: `bound` and
`expression` break on it, a `deadline` only needs it to arrive. Real MCAP logs, the real CLI.
"""

from __future__ import annotations

import contextlib
import io
import json

from astaa_deft.cli import main
from astaa_deft.engine.monitor import check_log
from astaa_deft.io.log.layout import SPEC_ATTACHMENT

from monitor_helpers import HandMadeLog, load, obstacle, obstacles, pose, spec_text

COLLISION = """
- name: no_collision
  kind: collision
  ego: {channel: localization, length: 4.0, width: 2.0}
  obstacles: {channel: obstacles, array: obstacles, id: id}
"""
DEEP = b"[" * 100_000 + b"]" * 100_000


def write_run(path, invariants: str, deep_at: int | None) -> None:
    spec = load(invariants)
    log = HandMadeLog(path, spec)
    log.writer.attachment(SPEC_ATTACHMENT, spec_text(invariants).encode(), "application/yaml")
    for k in range(40):  # the ego drives past an obstacle far to the side: never near it
        log.message("obstacles", 0.1 * k, obstacles(k, obstacle(7, 20.0, y=30.0)))
        log.message("localization", 0.1 * k + 0.05, DEEP if k == deep_at else pose(k, x=1.0 * k))
    log.event("run_stopping", 4.5)
    log.close()


def run_check(path) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = main(["check", str(path)])
    return code, out.getvalue()


def test_an_unreadable_message_withholds_the_pass(tmp_path):
    log = tmp_path / "run.mcap"
    write_run(log, COLLISION, deep_at=17)
    code, out = run_check(log)
    assert code == 3, out
    assert "verdict withheld: not every message was judged" in out
    assert "'no_collision' could not read 1 message (the payload does not decode)" in out
    assert "verdict: Pass" not in out


def test_the_same_run_without_the_damage_passes(tmp_path):
    log = tmp_path / "run.mcap"
    write_run(log, COLLISION, deep_at=None)
    code, out = run_check(log)
    assert code == 0 and "verdict: Pass" in out, out


def test_the_json_form_gives_no_verdict_and_says_why(tmp_path):
    log = tmp_path / "run.mcap"
    write_run(log, COLLISION, deep_at=3)
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = main(["check", str(log), "--json"])
    body = json.loads(out.getvalue())
    assert code == 3 and body["verdict"] is None and "no_collision" in body["unjudged"]


def test_monitors_that_judge_an_unreadable_message_themselves_still_do(tmp_path):
    invariants = COLLISION + """
- {name: pose_finite, kind: bound, channel: localization, field: x, finite: true}
- {name: pose_alive, kind: deadline, channel: localization, max_gap: 1.0}
"""
    log = tmp_path / "run.mcap"
    write_run(log, invariants, deep_at=17)
    from astaa_deft.io.log.reader import read_log

    result = check_log(read_log(log), load(invariants))
    assert [v.invariant for v in result.violations] == ["pose_finite"]  # the bound breaks on it
    assert "could not be decoded" in result.violations[0].detail
    assert result.unjudged == "'no_collision' could not read 1 message (the payload does not decode)"
    code, _ = run_check(log)
    assert code == 1  # a finding: the verdict stands, it is not a Pass


def test_proxy_withholds_the_pass_of_a_run_with_messages_its_monitors_could_not_read(tmp_path):
    """Live: the talker sends every 10th payload as garbage; a restart counter cannot be read on those."""
    from proxy_helpers import ECHO_SPEC, run_proxy

    spec = tmp_path / "echo.yaml"
    spec.write_text(ECHO_SPEC.read_text().replace("{spec_dir}", str(ECHO_SPEC.parent)) + (
        "invariants:\n  - {name: talker_up, kind: process, modules: [talker], restart_counter: header.seq}\n"))
    res = run_proxy(spec, "--duration", "3", "--run-dir", str(tmp_path / "run"), "--param", "count=100",
                    "--param", "garbage_every=10", "--record", str(tmp_path / "run.mcap"))
    assert res.returncode == 3, res.stdout + res.stderr
    assert "verdict withheld: not every message was judged ('talker_up' could not read 10 messages" in res.stdout
    assert "verdict: Pass" not in res.stdout
    code, out = run_check(tmp_path / "run.mcap")
    assert code == 3 and "'talker_up' could not read 10 messages" in out  # offline, the same
