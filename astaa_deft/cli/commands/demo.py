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

import argparse
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.model.records import RunMode, Verdict
from astaa_deft.demo.bundled import (  # noqa: F401
    DEMO_POLICY, demo_noise_policies, demo_policy_path, demo_scenario_names, demo_spec_path)
from astaa_deft.demo.status import StatusWatch
from astaa_deft.io.log import layout
from astaa_deft.io.output_place import Place, ready_dir, writing
from astaa_deft.engine.session.options import RunOptions, RunResult
from astaa_deft.cli.arguments import RUN_SECONDS, bounded
from astaa_deft.cli.commands.console import say
from astaa_deft.cli.commands.proxy import EXIT_NOT_OBSERVED, run_bus

if TYPE_CHECKING:
    from astaa_deft.cli.arguments import SubParsers
    from astaa_deft.model.sut import Spec

DEFAULT_TIME_LIMIT = 40.0


def add_parser(subparsers: SubParsers) -> None:
    """Declare the `demo` command and its `demo run` action."""
    demo = subparsers.add_parser("demo", help="the bundled driving stack through the whole tool: record, DeFT "
                                              "tests, live interception, minimisation, a short campaign",
                                epilog="examples:\n  astaa-deft demo\n  astaa-deft demo --scenario cut_in --out "
                                       "demo-cut-in\n"
                                       "  astaa-deft demo run --scenario cut_in --no-defects\n\n"
                                       f"bundled scenarios: {', '.join(demo_scenario_names())}")
    demo.add_argument("--scenario", default="lane_follow", help="a bundled scenario name or a scenario YAML path")
    demo.add_argument("--out", type=Path, default=Path("astaa-deft-demo"), help="where everything is written")
    demo.set_defaults(func=run)
    demo_sub = demo.add_subparsers(dest="demo_command", metavar="ACTION")
    demo_run = demo_sub.add_parser("run", help="run one demo scenario through the proxy", epilog="example:\n"
                                   "  astaa-deft demo run --scenario cut_in --record cut_in.mcap")
    demo_run.add_argument("--scenario", default="lane_follow", help="a bundled scenario name or a scenario YAML path")
    bounded(demo_run, "--duration", RUN_SECONDS, help="stop after S seconds (default: the scenario's time limit)")
    demo_run.add_argument("--no-defects", action="store_true", help="switch the demo's seeded defects off "
                                                                    "(default: on)")
    demo_run.add_argument("--passive", action="store_true", help="observe only, no star (default: the star proxy)")
    demo_run.add_argument("--record", type=Path,
                          help="where to write the log (default: astaa-deft-demo/SCENARIO.mcap)")
    demo_run.set_defaults(func=run_one)


def run(args: argparse.Namespace) -> int:
    """The parsed `demo` arguments to :func:`run_all`."""
    return run_all(args.scenario, args.out, sys.argv)


def run_one(args: argparse.Namespace) -> int:
    """The parsed `demo run` arguments to :func:`run_scenario`."""
    return run_scenario(args.scenario, duration=args.duration, defects=not args.no_defects, passive=args.passive,
                        record=args.record, command_line=sys.argv)


@dataclass(frozen=True, kw_only=True)
class DriveOptions:
    """One demo drive: the scenario, where its log goes, and how it runs."""

    scenario: str  # a bundled scenario name or a scenario YAML path
    record: Path  # the MCAP log to write
    defects: bool = True  # the demo's seeded defects on
    passive: bool = False  # observe only (no star)
    command_line: Sequence[str] = ()  # the command line stored in the log
    duration: float | None = None  # seconds (None: DEFAULT_TIME_LIMIT)
    policy: Path | None = None  # an ASTAA test case rewriting live messages
    stop_on_violation: bool = False
    spec: Spec | None = None  # the demo's spec as the command loaded it (None: loaded here)


def drive(options: DriveOptions) -> tuple[RunResult, StatusWatch]:
    """One scenario through the proxy, recorded; stops at the goal, a collision or the time limit.

    Returns the run's result and what the demo's status channel showed; raises what :func:`run_bus` raises.
    """
    from astaa_deft.engine.intercept import load_interceptor
    from astaa_deft.engine.spec.loader import load_spec

    spec = options.spec if options.spec is not None else load_spec(demo_spec_path())
    params = {"scenario": options.scenario, "defects": "on" if options.defects else "off"}
    policy = options.policy
    interceptor = load_interceptor(policy, spec) if policy is not None else None
    mode = RunMode.PASSIVE if options.passive else RunMode.STAR
    run_options = RunOptions(mode=mode, record=options.record, params=params,
                             command_line=list(options.command_line), interceptor=interceptor,
                             stop_on_violation=options.stop_on_violation,
                             attachments={layout.POLICY_ATTACHMENT: policy} if policy is not None else {})
    watch = StatusWatch()
    # The spec's run: section ends the run (goal, collision, the scenario's end); the watch keeps what to show.
    outcome = run_bus(spec, run_options, options.duration or DEFAULT_TIME_LIMIT,
                      on_start=lambda r: r.subscribe("status", watch.on_sample))
    return outcome, watch


def summarise(outcome: RunResult, watch: StatusWatch) -> None:
    """Print how the drive ended: goal, collision, mutations, verdict (or why it is withheld)."""
    from astaa_deft.engine.monitor.verdict import format_verdict
    from astaa_deft.engine.session.summary import untouched_policies

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


def run_scenario(scenario: str, *, duration: float | None, defects: bool, passive: bool, record: Path | None,
                 command_line: list[str]) -> int:
    """`demo run`: one scenario, recorded and summarised; exit 1 if it did not end well, 3 not fully observed,
    130 (Ctrl-C) or 143 (SIGTERM) when stopped before the scenario's end."""
    from astaa_deft.cli.commands.console import interrupted_exit_code, last_stop
    from astaa_deft.engine.session.summary import format_info
    from astaa_deft.io.log.reader import read_log

    if record is None:
        record = Path("astaa-deft-demo") / f"{Path(scenario).stem}.mcap"
        ready_dir(Place(record.parent, "--record"))
    say(f"demo: scenario '{scenario}', defects {'on' if defects else 'off'}, "
        f"{'passive' if passive else 'star'} proxy, log {record}")
    with writing(Place(record, "--record")):
        outcome, watch = drive(DriveOptions(scenario=scenario, record=record, defects=defects, passive=passive,
                                            command_line=command_line, duration=duration))
    say("")
    say("== summary ==")
    summarise(outcome, watch)
    say("")
    say(format_info(read_log(record)))
    if last_stop() is not None:  # stopped before the scenario's end: its summary above, the log finished
        return interrupted_exit_code()
    if not outcome.complete or not outcome.observed:
        return EXIT_NOT_OBSERVED
    ok = watch.goal and watch.collision is None and not outcome.crashes
    return 0 if ok else 1


# What the demo writes in its folder; a new demo there replaces them (one campaign journal, never two runs' mixed).
DEMO_OUTPUTS = ("clean.mcap", "planner-tests", "intercepted.mcap", "minimised", "campaign")


def run_all(scenario: str, out_dir: Path, command_line: list[str]) -> int:
    """`demo`: record, extract DeFT tests and run them, intercept live, minimise, fuzz. 0 if every step did its
    job, 1 if one did not, 130 (Ctrl-C) or 143 (SIGTERM) when stopped: the step under way ends as its command
    does on a stop, and no later step starts."""
    from astaa_deft.engine.spec.loader import load_spec

    place = Place(out_dir.resolve(), "--out")
    out_dir = ready_dir(place, temp=True)
    spec = load_spec(demo_spec_path())  # once for the tour: each step takes it as loaded here
    with writing(place):
        _start_fresh(out_dir)
        return _run_all(scenario, out_dir, command_line, spec)


def _start_fresh(out_dir: Path) -> None:
    """Remove what an earlier demo wrote in ``out_dir`` (only :data:`DEMO_OUTPUTS`), saying so."""
    import shutil

    earlier = [name for name in DEMO_OUTPUTS if (out_dir / name).exists()]
    if not earlier:
        return
    say(f"starting afresh: the earlier demo's {', '.join(earlier)} in {out_dir} are replaced")
    for name in earlier:
        path = out_dir / name
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()


def _stopped(step: str, out_dir: Path) -> int | None:
    """The exit code when a stop signal arrived during ``step`` (saying so and what is on disk), else None."""
    from astaa_deft.cli.commands.console import interrupted_exit_code, last_stop

    if last_stop() is None:
        return None
    written = [name for name in DEMO_OUTPUTS if (out_dir / name).exists()]
    say("")
    say(f"demo stopped by {last_stop()} during {step}; the later steps did not run"
        + (f"; written so far in {out_dir}: {', '.join(written)}" if written else ""))
    return interrupted_exit_code()


def _run_all(scenario: str, out_dir: Path, command_line: list[str], spec: Spec) -> int:
    from astaa_deft.engine.bus import process_launch
    from astaa_deft.analysis.deft.workflow import ExtractOptions
    from astaa_deft.cli.commands.console import forget_stop, stop_as_interrupt
    from astaa_deft.cli.commands.extract import extract

    problems: list[str] = []
    forget_stop()

    say(f"== 1/5 record: the demo stack drives '{scenario}' through the star proxy ==")
    clean_log = out_dir / "clean.mcap"
    outcome, watch = drive(DriveOptions(scenario=scenario, record=clean_log, command_line=command_line, spec=spec))
    summarise(outcome, watch)
    if (code := _stopped("step 1 (record)", out_dir)) is not None:
        return code
    if not watch.goal or not outcome.passed:
        problems.append("the clean run did not reach its goal with a Pass verdict")

    say("")
    say("== 2/5 DeFT: deterministic planner tests from that record ==")
    tests_dir = out_dir / "planner-tests"
    extract(clean_log, spec, tests_dir, ExtractOptions(ground_truth="debug.inputs"))
    if (code := _stopped("step 2 (DeFT extraction)", out_dir)) is not None:
        return code
    say(f"$ pytest {tests_dir.relative_to(Path.cwd()) if tests_dir.is_relative_to(Path.cwd()) else tests_dir}")
    try:
        with stop_as_interrupt():  # the pytest child in its own process group: stopped by the launcher
            result = process_launch.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                                         str(tests_dir)], timeout=None, cwd=str(out_dir))
    except KeyboardInterrupt:
        return _stopped("step 2 (the module tests' pytest run)", out_dir) or 130
    say(result.stdout.strip().splitlines()[-1] if result.stdout.strip() else result.stderr.strip())
    if result.returncode != 0:
        problems.append("the extracted planner tests did not pass")

    say("")
    policy = demo_policy_path()
    say(f"== 3/5 ASTAA: the same scenario with live messages rewritten ({policy.name}) ==")
    say(policy.read_text().split("<description>")[1].split("</description>")[0].strip())
    attack_log = out_dir / "intercepted.mcap"
    outcome, watch = drive(DriveOptions(scenario=scenario, record=attack_log, command_line=command_line, policy=policy,
                                        duration=20.0, spec=spec))
    summarise(outcome, watch)
    if (code := _stopped("step 3 (live interception)", out_dir)) is not None:
        return code
    if outcome.verdict is None or outcome.verdict.klass == Verdict.PASS:
        problems.append("the interception did not make any invariant break")
    elif not outcome.complete or not outcome.observed:
        problems.append(f"the intercepted run was not fully observed ({outcome.end_reason})")

    say("")
    say("== 4/5 minimise: which mutations cause that failure? ==")
    try:
        with stop_as_interrupt():
            minimised = minimise_step(attack_log, spec, out_dir / "minimised")
    except KeyboardInterrupt:
        minimised = 130
    if (code := _stopped("step 4 (minimise)", out_dir)) is not None:
        return code
    if minimised != 0:
        problems.append("minimisation did not reproduce the failure")

    say("")
    say("== 5/5 fuzz: a short campaign finds defects on its own ==")
    from astaa_deft.orchestration.campaign.demo_step import campaign_step

    with stop_as_interrupt():  # SIGTERM stops the campaign as Ctrl-C does: its journal and report stay readable
        found = campaign_step(demo_spec_path(), out_dir / "campaign", say, spec=spec)
    if (code := _stopped("step 5 (fuzz)", out_dir)) is not None:
        return code
    if found == 0:
        problems.append("the campaign found no failure")

    say("")
    say(f"everything is in {out_dir}/: clean.mcap, planner-tests/, intercepted.mcap, minimised/, campaign/")
    say(f"look inside a log: astaa-deft log info {attack_log}")
    for p in problems:
        say(f"demo problem: {p}")
    return 1 if problems else 0


def minimise_step(log: Path, spec: Spec, out_dir: Path) -> int:
    """Step 4 of the demo: minimise the intercepted run's failure into ``out_dir``; the command's exit code."""
    from astaa_deft.analysis.minimise.workflow import MinimiseOptions
    from astaa_deft.cli.commands.minimise import minimise

    # One live confirmation of the minimised test case keeps the demo short; the CLI defaults to 3.
    return minimise(log, out_dir, MinimiseOptions(spec_path=spec.path or demo_spec_path(), spec=spec, repeats=1,
                                                  parallel=2, live_only=False, confirm=1))
