"""In a campaign, every confirmed bucket whose failing module the spec can replay gets module tests that fail on
its defect — zoo members with seeded defects, inputs on slow channels included.

A real campaign (baseline, cases in worker processes on Zenoh, re-runs and
unmutated twins, the journal in SQLite, minimisation in a child process, the
module tests written and run once) on generated zoo stacks (tests/zoo) whose
module has a seeded defect:

* ``nan_state``: a NaN input goes into the module's warm state unchecked and
  the *next* cycle raises on that state — the failing cycle's own inputs are
  clean, so only a suite that carries the state from the frames before it
  fails on the defect;
* ``crash_on_nan``: the cycle given a NaN raises.

The mutated input is channel c at 1 Hz (absent for the MPC member's first
outputs), the path channel on which three of seven buckets of a third-party
MPC stack got no module tests: a module replayed per output (its frames
found per recorded output) that dies on a cycle has no output there, so the
minimiser's module replay cannot show the crash and it minimises live,
writing no tests; the campaign then extracts the module's DeFT suite from the
failing run and adds the frame of the failing cycle. Each suite is run by
pytest in a child process, as a user runs it: it fails on the defect; a copy
whose stored spec turns the defect off no longer fails on it (the tool's own
judgement, ``judge_pytest``; a minimiser's suite passes outright).
"""

from __future__ import annotations

import dataclasses
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.orchestration.campaign.module_tests import judge_pytest, replayable
from zoo import MPC, Member, write_member
from zoo.campaign import CampaignFound, nan_case, run_campaign, run_suite
from zoo.runtime.zoo_module import Step

# Short: a module that answers the newest trigger when idle (one output per frame found: per_output), its warm
# state carrying a NaN from the 1 Hz channel c into the next cycle, which dies of it.
SLOW_STATE = Member("camp_slow_state", trigger="newest_idle", readiness="slow_1hz", reading="latched", state="warm",
                    cost_ms=(2.0, 6.0), seconds=2.5, defect="nan_state")
STATE_SAYS = "a non-finite state from an earlier cycle"


def check_every_replayable_bucket(found: CampaignFound, scratch: Path, *, says: str,
                                  seeded_only: bool = True) -> list[str]:
    """The acceptance line on one finished campaign: every confirmed bucket of a replayable module has a
    suite, the campaign's check says it fails on the defect, pytest agrees (its output says ``says``), and
    with the seeded defect off it no longer fails on it. ``seeded_only``: every bucket is the seeded defect.
    The buckets checked."""
    buckets = found.replayable()
    log = "\n".join(found.said)
    for bucket in buckets:
        suite = found.suite(bucket)
        assert suite is not None and (suite / "deft.json").is_file(), (bucket, log)
        checked = found.module_tests[bucket.bucket]
        assert checked.fails_on_defect is True, (bucket, checked, log)
        on = run_suite(suite)
        assert on.failed, (bucket.bucket, on.output[-3000:])
        verdict = judge_pytest(on.returncode, on.output, crash=True)
        assert verdict.fails_on_defect is True and says in on.output, (bucket.bucket, verdict, on.output[-3000:])
        if "zoo seeded defect" not in on.output:
            assert not seeded_only, (bucket.bucket, on.output[-3000:])
            continue  # the module died of something else (an input array too short): no defect to turn off
        off = run_suite(suite, defect="none", scratch=scratch)
        assert judge_pytest(off.returncode, off.output, crash=True).fails_on_defect is False, (
            bucket.bucket, off.output[-3000:])
        assert "zoo seeded defect" not in off.output, off.output[-3000:]
    return [b.bucket for b in buckets]


def test_the_state_defect_needs_the_state_and_the_spec_replays_the_module(tmp_path):
    frame = lambda seq, v: {name: {"header": {"seq": seq, "stamp": 0.0}, "v": v if name == "c" else [0.1, 0.2]}  # noqa: E731
                            for name in ("a", "b", "c")}
    step = Step(state="warm", defect="nan_state", cost_ms="0.01")
    assert math.isnan(step.step(frame(1, [math.nan, 0.0]))["x"][0])  # the NaN goes into the state unchecked
    with pytest.raises(ValueError, match="a non-finite state from an earlier cycle"):
        step.step(frame(2, [0.3, 0.4]))  # clean inputs: the state carried from the cycle before raises
    assert Step(state="warm", defect="nan_state", cost_ms="0.01").step(frame(2, [0.3, 0.4])) is not None  # fresh
    spec = load_spec(write_member(SLOW_STATE, tmp_path / "stack").spec_path)
    assert replayable(spec, "module") and not replayable(spec, "producer") and not replayable(spec, None)


@pytest.mark.slow  # ~1 min: a whole campaign with its baseline; the member's own replay stays in the default run
@pytest.mark.promise
def test_a_state_defect_reached_through_a_slow_channel_gets_module_tests_that_fail_on_it(tmp_path):
    stack = write_member(SLOW_STATE, tmp_path / "stack")
    found = run_campaign(stack, tmp_path / "campaign", cases=[nan_case("c")], reruns=1)
    log = "\n".join(found.said)
    checked = check_every_replayable_bucket(found, tmp_path, says=STATE_SAYS)
    assert len(checked) == 1, log  # the case's bucket, confirmed, blamed on the module, which the spec replays
    bucket = found.replayable()[0]
    assert bucket.family.startswith("c:"), bucket
    # The minimiser's module replay of a per-output module cannot show a crash (no output on that cycle): the
    # campaign's own DeFT suite of the failing run carries the state into the failing cycle's frame.
    suite = found.suite(bucket)
    assert suite is not None and suite.name.endswith("-replay"), log


@pytest.mark.slow  # ~3 min: four campaigns, two with the random strategy
@pytest.mark.parametrize(("name", "member", "says"), [
    # The stranger's MPC rebuilt (15 Hz, newest trigger when idle, warm start, its 1 Hz input c absent at first).
    ("mpc_crash", dataclasses.replace(MPC, defect="crash_on_nan", seconds=3.0), "NaN in input"),
    ("mpc_state", dataclasses.replace(MPC, defect="nan_state", seconds=3.0), STATE_SAYS),
    # Every trigger answered (per_trigger): the minimiser replays the module and writes the failing tests.
    ("each_state", Member("camp_each_state", readiness="slow_1hz", state="warm", seconds=3.0, defect="nan_state"),
     STATE_SAYS),
])
def test_scripted_campaigns_on_zoo_members_with_seeded_defects(tmp_path, name, member, says):
    stack = write_member(member, tmp_path / "stack")
    found = run_campaign(stack, tmp_path / "campaign", cases=[nan_case("c"), nan_case("b", after_s=1.2)])
    checked = check_every_replayable_bucket(found, tmp_path, says=says)
    assert any(b.family.startswith("c:") for b in found.replayable()), (checked, "\n".join(found.said))


@pytest.mark.slow  # ~1-2 min: `astaa-deft fuzz` as a user runs it, the random strategy
def test_the_fuzz_command_on_a_slow_channel_member_every_bucket_gets_failing_module_tests(tmp_path):
    member = Member("camp_fuzz", trigger="newest_idle", readiness="slow_1hz", state="warm", cost_ms=(2.0, 6.0),
                    seconds=3.0, defect="crash_on_nan")
    stack = write_member(member, tmp_path / "stack")
    out = tmp_path / "campaign"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).resolve().parent.parent),
                                                         os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "fuzz", "--spec", str(stack.spec_path), "-o",
                           str(out), "--cases", "10", "--workers", "2", "--seed", "1",
                           "--no-module-level"],  # the live buckets' suites (the module level's: test_module_level)
                          capture_output=True, text=True, timeout=900, env=env)
    assert done.returncode in (0, 1), done.stdout[-3000:] + done.stderr[-3000:]
    from astaa_deft.orchestration.journal.journal import open_existing

    journal = open_existing(out)
    try:
        found = CampaignFound(stack, out, done.stdout.splitlines(), journal.buckets(), journal.module_tests(),
                              {n: r.status for n, r in journal.minimisations().items()})
    finally:
        journal.close()
    # Every bucket here is the module dying (the seeded NaN, or an input array too short for it): a crash.
    checked = check_every_replayable_bucket(found, tmp_path, says="", seeded_only=False)
    assert checked, done.stdout[-3000:]
