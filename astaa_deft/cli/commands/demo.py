"""`astaa-deft demo`: the bundled driving stack through the whole tool.

`demo run` drives one scenario through the star proxy, records it and
summarises the run. `demo` alone runs the main job end to end:
1. record a clean run through the proxy, with online monitors and a verdict;
2. DeFT: extract deterministic planner tests from that log and run them with pytest;
3. ASTAA: replay the scenario with a test case that rewrites live messages
   (a NaN speed limit in routing) and show what changed and what broke;
4. minimise that failure down to the mutation that causes it.
Everything lands in ./astaa-deft-demo/ (or --out).
"""

from __future__ import annotations

import sys
from pathlib import Path

from astaa_deft.model.records import Verdict
from astaa_deft.demo.bundled import DEMO_POLICY, demo_noise_policies, demo_policy_path, demo_spec_path  # noqa: F401
from astaa_deft.engine.bus import process_launch
from astaa_deft.demo.status import StatusWatch
from astaa_deft.engine.session.summary import untouched_policies
from astaa_deft.engine.intercept import load_interceptor
from astaa_deft.io.log import layout
from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.session.summary import format_info
from astaa_deft.engine.monitor.verdict import format_verdict
from astaa_deft.io.output_place import Place, ready_dir, writing
from astaa_deft.engine.session import RunOptions, RunResult
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.cli.commands.console import say
from astaa_deft.cli.commands.proxy import EXIT_NOT_OBSERVED, run_bus

DEFAULT_TIME_LIMIT = 40.0


def drive(scenario: str, defects: bool, passive: bool, record: Path, command_line: list[str],
          duration: float | None = None, policy: Path | None = None, stop_on_violation: bool = False,
          ) -> tuple[RunResult, StatusWatch]:
    """One scenario through the proxy, recorded; stops at the goal, a collision or the time limit."""
    spec = load_spec(demo_spec_path())
    params = {"scenario": scenario, "defects": "on" if defects else "off"}
    interceptor = load_interceptor(policy, spec) if policy is not None else None
    options = RunOptions(mode="passive" if passive else "star", record=record, params=params,
                         command_line=command_line, interceptor=interceptor, stop_on_violation=stop_on_violation,
                         attachments={layout.POLICY_ATTACHMENT: policy} if policy is not None else {})
    watch = StatusWatch()
    # The spec's run: section ends the run (goal, collision, the scenario's end); the watch keeps what to show.
    outcome = run_bus(spec, options, duration or DEFAULT_TIME_LIMIT,
                      on_start=lambda r: r.subscribe("status", watch.on_sample))
    return outcome, watch


def summarise(outcome: RunResult, watch: StatusWatch) -> None:
    st = watch.latest
    say(f"stopped: {outcome.end_reason} after {outcome.seconds:.1f} s wall, sim time {st.get('sim_time', 0):.1f} s")
    say(f"goal reached: {'yes' if watch.goal else 'no'}")
    if watch.collision is not None:
        say(f"collision: yes, with {watch.collision.get('collision_with', '?')} "
            f"at sim time {watch.collision.get('sim_time', 0):.1f} s")
    else:
        say("collision: no")
    if outcome.mutations:
        say(f"mutations applied: {outcome.mutations}")
    for line in untouched_policies(outcome.policies):
        say(line)
    if not outcome.complete or not outcome.observed:
        say(f"verdict withheld: the run was not fully observed ({outcome.end_reason})")
    elif outcome.verdict is not None:
        say(format_verdict(outcome.verdict))


def run(scenario: str, duration: float | None, defects: bool, passive: bool, record: Path | None,
        command_line: list[str]) -> int:
    """`demo run`: one scenario, recorded and summarised; exit 1 if it did not end well."""
    if record is None:
        record = Path("astaa-deft-demo") / f"{Path(scenario).stem}.mcap"
        ready_dir(Place(record.parent, "--record"))
    say(f"demo: scenario '{scenario}', defects {'on' if defects else 'off'}, "
        f"{'passive' if passive else 'star'} proxy, log {record}")
    with writing(Place(record, "--record")):
        outcome, watch = drive(scenario, defects, passive, record, command_line, duration)
    say("")
    say("== summary ==")
    summarise(outcome, watch)
    say("")
    say(format_info(read_log(record)))
    if not outcome.complete or not outcome.observed:
        return EXIT_NOT_OBSERVED
    ok = watch.goal and watch.collision is None and not outcome.crashes
    return 0 if ok else 1


def run_all(scenario: str, out_dir: Path, command_line: list[str]) -> int:
    """`demo`: record, extract DeFT tests and run them, intercept live, minimise. 0 if every step did its job."""
    place = Place(out_dir.resolve(), "--out")
    out_dir = ready_dir(place, temp=True)
    with writing(place):
        return _run_all(scenario, out_dir, command_line)


def _run_all(scenario: str, out_dir: Path, command_line: list[str]) -> int:
    spec_path = demo_spec_path()
    problems: list[str] = []

    say(f"== 1/5 record: the demo stack drives '{scenario}' through the star proxy ==")
    clean_log = out_dir / "clean.mcap"
    outcome, watch = drive(scenario, True, False, clean_log, command_line)
    summarise(outcome, watch)
    if not watch.goal or not outcome.passed:
        problems.append("the clean run did not reach its goal with a Pass verdict")

    say("")
    say("== 2/5 DeFT: deterministic planner tests from that record ==")
    tests_dir = out_dir / "planner-tests"
    from astaa_deft.cli.commands.extract import run as extract

    extract(clean_log, spec_path, tests_dir, threshold=None, process=False, ground_truth="debug.inputs")
    say(f"$ pytest {tests_dir.relative_to(Path.cwd()) if tests_dir.is_relative_to(Path.cwd()) else tests_dir}")
    result = process_launch.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(tests_dir)],
                                timeout=None, cwd=str(out_dir))
    say(result.stdout.strip().splitlines()[-1] if result.stdout.strip() else result.stderr.strip())
    if result.returncode != 0:
        problems.append("the extracted planner tests did not pass")

    say("")
    policy = demo_policy_path()
    say(f"== 3/5 ASTAA: the same scenario with live messages rewritten ({policy.name}) ==")
    say(policy.read_text().split("<description>")[1].split("</description>")[0].strip())
    attack_log = out_dir / "intercepted.mcap"
    outcome, watch = drive(scenario, True, False, attack_log, command_line, policy=policy, duration=20.0)
    summarise(outcome, watch)
    if outcome.verdict is None or outcome.verdict.klass == Verdict.PASS:
        problems.append("the interception did not make any invariant break")
    elif not outcome.complete or not outcome.observed:
        problems.append(f"the intercepted run was not fully observed ({outcome.end_reason})")

    say("")
    say("== 4/5 minimise: which mutations cause that failure? ==")
    if minimise_step(attack_log, spec_path, out_dir / "minimised") != 0:
        problems.append("minimisation did not reproduce the failure")

    say("")
    say("== 5/5 fuzz: a short campaign finds defects on its own ==")
    from astaa_deft.orchestration.campaign.demo_step import campaign_step

    if campaign_step(spec_path, out_dir / "campaign", say) == 0:
        problems.append("the campaign found no failure")

    say("")
    say(f"everything is in {out_dir}/: clean.mcap, planner-tests/, intercepted.mcap, minimised/, campaign/")
    say(f"look inside a log: astaa-deft log info {attack_log}")
    for p in problems:
        say(f"demo problem: {p}")
    return 1 if problems else 0


def minimise_step(log: Path, spec: Path, out_dir: Path) -> int:
    from astaa_deft.cli.commands import minimise

    # One live confirmation of the minimised test case keeps the demo short; the CLI defaults to 3.
    return minimise.run(log, spec, None, out_dir, repeats=1, parallel=2, live_only=False, confirm=1)
