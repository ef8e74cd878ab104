"""The run's end dated when it happened: a module whose exit ends the run falls silent at its last message and
takes its shutdown delay to exit (results written, sessions closed); a 0.2 s deadline on its partner's output must
not break in that shutdown, however long the tool takes to notice the exit. An exit later than the module's
shutdown delay ends the run at the exit itself (docs/spec.md, "How a run ends").

tests/sut/ticks.yaml: the simulator (tick_sim.py) exits ``teardown`` seconds
after its last tick; the controller answers each of its ego messages on
'command' (control_gap: deadline, max_gap 0.2). Real modules, real Zenoh, a
real log. The many-runs-under-load form is ``-m slow`` (and
benchmarks/bench_run_end.py).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from astaa_deft.engine.monitor import check_log
from astaa_deft.engine.session import RunOptions, run_session
from astaa_deft.engine.session.run_end import SHUTDOWN_GRACE_NS, RunEndWatch
from astaa_deft.engine.spec.loader import load_spec, load_spec_text
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import read_log
from astaa_deft.model.errors import InputError
from astaa_deft.orchestration.campaign.baseline import (
    LEARNING_SHUTDOWN_DELAY, learned_shutdown_delays, learning_shutdown_delays,
)
from astaa_deft.orchestration.journal.model import CaseOutcome
from stack_timing import unexplained

TICKS = Path(__file__).parent / "sut" / "ticks.yaml"
LOAD = "while True: pass"  # one core kept busy
RUNS = 50
ENDING = "{module: sim, reason: scenario over}"


def _run(tmp_path: Path, name: str, ticks: int = 12, teardown: float = 0.3, delays: dict | None = None):
    log = tmp_path / f"{name}.mcap"
    result = run_session(load_spec(TICKS), RunOptions(record=log, run_dir=tmp_path / name, time_limit=30.0,
                                                      params={"ticks": str(ticks), "teardown": str(teardown)},
                                                      shutdown_delays=delays or {}))
    return result, log


def _ends(log: Path):
    """The log's run_end event, the simulator's exit and its last tick."""
    contents = read_log(log)
    [end] = contents.records(rec.RunEnd)
    [exit_] = [e for e in contents.records(rec.ProcessExit) if e.module == "sim"]
    last_tick = max(m.publish_time for m in contents.messages if m.topic in ("sim/ego", "sim/vehicles"))
    return contents, end, exit_, last_tick


def _findings_at_the_end(result, log: Path) -> list[str]:
    """Deadline findings after the controller's last answer: the end's silence (a stall mid-run is followed by
    another answer in the log, and is a true finding about that run)."""
    answers = len(read_log(log).on("sim/command"))
    return [v.detail for v in result.violations
            if v.invariant_kind == "deadline" and (v.seq is None or v.seq >= answers)]


def test_the_end_is_dated_at_the_ending_modules_last_message_and_no_deadline_breaks_after_it(tmp_path):
    result, log = _run(tmp_path, "one")
    assert result.end_reason == "scenario over"
    assert _findings_at_the_end(result, log) == [], result.verdict.summary
    # A stall mid-run that the controller's own stamps show (a loaded machine's) is a true finding of that run.
    assert unexplained(result.violations, read_log(log), load_spec(TICKS)) == [], result.verdict.summary
    if not result.violations:
        assert result.verdict.klass == "Pass", result.verdict.summary
    contents, end, exit_, last_tick = _ends(log)
    # the simulator's last message, not when the tool noticed its exit (and not its exit, which came later)
    assert end.time_ns == last_tick < exit_.time_ns <= last_tick + SHUTDOWN_GRACE_NS
    stopping = contents.records(rec.RunStopping)[0].time_ns
    assert stopping > end.time_ns
    offline = check_log(contents, load_spec(TICKS))
    assert offline.end_ns == end.time_ns and offline.verdict.klass == result.verdict.klass, offline.verdict.summary


def test_an_exit_later_than_the_shutdown_delay_ends_the_run_at_the_exit_itself(tmp_path):
    # 1.6 s of teardown against the default 1 s: the silence before the exit is part of the run, judged to the
    # exit as waitpid saw it (not to "exit - 1 s", which no rule names)
    result, log = _run(tmp_path, "late", teardown=1.6)
    assert result.end_reason == "scenario over"
    _, end, exit_, last_tick = _ends(log)
    assert exit_.time_ns - last_tick > SHUTDOWN_GRACE_NS
    assert end.time_ns == exit_.time_ns
    assert result.shutdowns["sim"] == pytest.approx((exit_.time_ns - last_tick) / 1e9, abs=0.01)


def test_a_learned_shutdown_delay_dates_a_slow_exit_at_the_last_message(tmp_path):
    result, log = _run(tmp_path, "learned", teardown=1.6, delays={"sim": 3.5})
    assert result.end_reason == "scenario over"
    _, end, exit_, last_tick = _ends(log)
    assert end.time_ns == last_tick < exit_.time_ns
    assert _findings_at_the_end(result, log) == []
    assert 1.6 <= result.shutdowns["sim"] <= 3.5


def test_the_specs_shutdown_delay_is_read_and_wins_over_a_learned_one():
    text = TICKS.read_text()
    assert text.count(ENDING) == 1
    spec = load_spec_text(text.replace(ENDING, "{module: sim, reason: scenario over, shutdown_delay: 3}"),
                          name=str(TICKS), base_dir=TICKS.parent)
    [ending] = spec.run.module_exits
    assert ending.shutdown_delay == 3.0
    assert RunEndWatch(spec, {"sim": 7.0}).grace_ns("sim") == 3_000_000_000
    plain = load_spec(TICKS)
    assert RunEndWatch(plain, {"sim": 7.0}).grace_ns("sim") == 7_000_000_000
    assert RunEndWatch(plain).grace_ns("sim") == SHUTDOWN_GRACE_NS


@pytest.mark.parametrize("value, says", [("-1", "must be greater than 0"), ("7200", "must be at most 3600"),
                                         ("soon", "must be a finite number")])
def test_a_bad_shutdown_delay_is_one_located_error(value, says):
    text = TICKS.read_text().replace(ENDING, f"{{module: sim, reason: scenario over, shutdown_delay: {value}}}")
    with pytest.raises(InputError) as caught:
        load_spec_text(text, name="ticks.yaml", base_dir=TICKS.parent)
    [problem] = caught.value.problems
    assert "'shutdown_delay'" in str(problem) and says in str(problem) and str(problem).startswith("ticks.yaml:")


def test_the_baseline_learns_each_ending_modules_shutdown_delay_with_headroom():
    def clean(**shutdowns):
        return CaseOutcome(status="done", verdict="Pass", summary="Pass", shutdowns=shutdowns)
    # the longest shutdown × 2 + 0.5 s; never under the default grace; a longer wait than the baseline's own
    # delay was a silence (its run ended at the exit), not a shutdown; and never past that delay
    assert learned_shutdown_delays([clean(sim=0.4), clean(sim=1.54)]) == {"sim": 3.6}
    assert learned_shutdown_delays([clean(sim=0.1)]) == {"sim": SHUTDOWN_GRACE_NS / 1e9}
    assert learned_shutdown_delays([clean(sim=2.0), clean(sim=LEARNING_SHUTDOWN_DELAY + 5)]) == {"sim": 4.5}
    assert learned_shutdown_delays([clean(sim=6.0)]) == {"sim": LEARNING_SHUTDOWN_DELAY}
    assert learned_shutdown_delays([CaseOutcome(status="done", verdict="Pass", summary="Pass")]) == {}
    assert learning_shutdown_delays(load_spec(TICKS)) == {"sim": LEARNING_SHUTDOWN_DELAY}


def _campaign_runs(tmp_path: Path, teardown: float, baseline: int, runs: int, prefix: str):
    """The campaign's way: ``baseline`` clean runs date their end with the baseline's own delay and teach the
    module's shutdown delay; ``runs`` more date theirs by what they taught. Each run's end findings."""
    taught, found = [], []
    for n in range(baseline + runs):
        delays = learned_shutdown_delays(taught) if n >= baseline else learning_shutdown_delays(load_spec(TICKS))
        result, log = _run(tmp_path, f"{prefix}{n}", teardown=teardown, delays=delays)
        assert result.end_reason == "scenario over", result.end_reason
        if n < baseline:
            taught.append(CaseOutcome(status="done", verdict="Pass", summary="Pass", shutdowns=result.shutdowns))
        found += [f"run {n} (teardown {teardown} s, delays {delays}): {d}" for d in _findings_at_the_end(result, log)]
    return found


def test_a_module_exiting_three_seconds_after_its_last_message_gives_no_finding_at_the_end(tmp_path):
    # 3 s is three times the default grace; one baseline run teaches it, two more runs are dated by it.
    # The 50-runs-under-load form (0.5-3 s) is -m slow and benchmarks/bench_run_end.py.
    assert _campaign_runs(tmp_path, 3.0, baseline=1, runs=2, prefix="r") == []


@pytest.mark.slow
def test_fifty_clean_runs_under_cpu_load_give_no_deadline_finding_at_their_end(tmp_path):
    # Two busy loops on top of whatever else the machine runs; modules whose exit takes 0.5, 1.5 and 3 s after
    # their last tick, each with a baseline of two runs. A controller stalled by the load mid-run (its answers
    # really came more than 0.2 s apart, as the log shows) is a true finding about that run and is not counted;
    # what must never come is the false one: the silence after the last answer, which only a shutdown dated
    # wrongly would make longer than 0.2 s.
    burners = [subprocess.Popen([sys.executable, "-c", LOAD]) for _ in range(2)]
    try:
        at_end = [f for teardown in (0.5, 1.5, 3.0)
                  for f in _campaign_runs(tmp_path, teardown, baseline=2, runs=15, prefix=f"t{teardown}-")]
    finally:
        for burner in burners:
            burner.kill()
            burner.wait()
    print(f"{3 * 17} runs: {len(at_end)} deadline findings at the end")
    assert at_end == []
