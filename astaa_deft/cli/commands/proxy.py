"""`astaa-deft proxy`: run the SUT through the star (or watch it passively) and record it.

Exit codes: 0 the run passes (or ended without a verdict and without a crash), 1 a finding, 3 the run was
not fully observed (no verdict can be given); bad input raises InputError (exit 2, printed by the CLI).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.cli.arguments import RUN_SECONDS, bounded
from astaa_deft.cli.commands.console import RateMeter, StatusLine, StopSignal, format_event, parse_params, say
from astaa_deft.engine.session.options import RunOptions, RunResult
from astaa_deft.model.records import RunMode, Verdict
from astaa_deft.io.log import records as rec
from astaa_deft.io.output_place import Place, writing

if TYPE_CHECKING:
    from astaa_deft.cli.arguments import SubParsers
    from astaa_deft.engine.session import RunView
    from astaa_deft.model.sut import Spec


MUTATIONS_SHOWN = 3
EXIT_NOT_OBSERVED = 3  # the tool lost its recorder or bus router: no verdict can be given


def add_parser(subparsers: SubParsers) -> None:
    """Declare the `proxy` command."""
    proxy = subparsers.add_parser("proxy", help="run the SUT through the proxy and record the bus", epilog=(
        "examples:\n  astaa-deft proxy --spec specs/demo_av.yaml --record run.mcap --duration 30\n"
        "  astaa-deft proxy --spec specs/demo_av.yaml --policy policies/examples/demo_nan_speed_limit.xml "
        "--record attacked.mcap\n  astaa-deft proxy --spec sut.yaml --no-launch --passive --record run.mcap"))
    proxy.add_argument("--spec", type=Path, required=True, help="the SUT spec (YAML)")
    proxy.add_argument("--record", type=Path, help="write the MCAP test log here (default: no log)")
    proxy.add_argument("--passive", action="store_true",
                       help="observe only (no man in the middle): adds nothing to the SUT's message path "
                            "(default: the star proxy)")
    bounded(proxy, "--duration", RUN_SECONDS, help="stop after S seconds (default: until Ctrl-C)")
    proxy.add_argument("--launch", action=argparse.BooleanOptionalAction, default=True,
                       help="start the spec's modules (default) or attach to a running SUT (--no-launch)")
    proxy.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                       help="override a spec param used in module commands (repeatable; default: the spec's values)")
    proxy.add_argument("--run-dir", type=Path, help="keep module logs and Zenoh configs here (default: a "
                                                    "temporary folder)")
    proxy.add_argument("--stop-on-violation", action="store_true", help="end the run at the first broken "
                                                                        "invariant (default: run on)")
    proxy.add_argument("--policy", type=Path,
                       help="an ASTAA test case (XML): rewrite, drop, delay or inject live messages "
                            "(default: none, messages pass unchanged)")
    proxy.add_argument("--dictionary", type=Path, action="append", default=[],
                       help="an exceptional-value dictionary on top of the default one (repeatable; "
                            "default: the bundled one only)")
    proxy.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The parsed `proxy` arguments: load the spec (and the test case, if any) into RunOptions, :func:`run_proxy`."""
    from astaa_deft.engine.spec.loader import load_spec

    spec = load_spec(args.spec)
    interceptor, attachments = None, {}
    if args.policy is not None:
        from astaa_deft.engine.intercept import load_interceptor
        from astaa_deft.io.log import layout

        interceptor = load_interceptor(args.policy, spec, args.dictionary)
        attachments[layout.POLICY_ATTACHMENT] = args.policy
        for n, path in enumerate(args.dictionary, start=1):
            attachments[layout.DICTIONARY_ATTACHMENT.format(n=n)] = path
    options = RunOptions(mode=RunMode.PASSIVE if args.passive else RunMode.STAR, launch=args.launch, record=args.record,
                         params=parse_params(args.param), command_line=sys.argv, run_dir=args.run_dir,
                         stop_on_violation=args.stop_on_violation, interceptor=interceptor,
                         attachments=attachments)
    return run_proxy(spec, options, duration=args.duration)


def run_bus(spec: Spec, options: RunOptions, duration: float | None, *,
            until: Callable[[RunView], str | None] = lambda run: None,
            on_start: Callable[[RunView], None] = lambda run: None, verbose: bool = True) -> RunResult:
    """:func:`run_session` with the console: events as they come, a status line, Ctrl-C/SIGTERM to stop.

    ``duration`` (seconds, None: no limit) caps ``options.time_limit`` (for this run: the options are not changed);
    ``until(run)`` returns a reason to stop or None; ``on_start(run)`` is called once the run is up;
    ``verbose`` False prints no events. Returns the run's result; raises what :func:`run_session` raises.
    Main thread only (it installs the SIGINT/SIGTERM handlers).
    """
    from astaa_deft.engine.session import run_session

    shown: dict[str, int] = {}

    def on_event(record: rec.Record) -> None:
        if isinstance(record, rec.MutationRecord):  # a policy may fire at 50 Hz: show the first few of each
            shown[record.policy] = shown.get(record.policy, 0) + 1
            if shown[record.policy] > MUTATIONS_SHOWN:
                if shown[record.policy] == MUTATIONS_SHOWN + 1 and verbose:
                    say(f"~~ (further mutations of policy {record.policy} are in the log, not shown)")
                return
        text = format_event(record)
        if text and verbose:
            status.clear()
            say(text)

    if duration is not None:
        options = replace(options, time_limit=duration if options.time_limit is None
                          else min(duration, options.time_limit))
    status = StatusLine(lambda: "")
    with StopSignal() as stop:

        def started(run: RunView) -> None:
            meter = RateMeter(run.counts)
            t0 = time.monotonic()
            status.render = lambda: _status(run, meter, t0)
            status.__enter__()
            on_start(run)

        def stop_when(run: RunView) -> str | None:
            if stop.requested():
                return f"signal {stop.received}"
            return until(run)

        try:
            return run_session(spec, options, stop_when=stop_when, on_event=on_event, on_start=started)
        finally:
            status.__exit__()


def _status(run: RunView, meter: RateMeter, t0: float) -> str:
    rates = meter.rates()
    parts = [f"{name} {rate:.0f}/s" for name, rate in rates.items()]
    crashes = len(run.crashed())
    return f"[{time.monotonic() - t0:6.1f} s] " + " | ".join(parts) + (f" | crashes {crashes}" if crashes else "")


def run_proxy(spec: Spec, options: RunOptions, *, duration: float | None) -> int:
    """One run of ``spec`` as ``options`` say, for at most ``duration`` seconds (None: until Ctrl-C).

    Prints the run's events, counts, verdict; returns the exit code (:func:`exit_code`). Raises InputError
    for a ``--param`` value the spec does not allow, OutputError when the log or run directory cannot be
    written.
    """
    from astaa_deft.engine.session.summary import untouched_policies
    from astaa_deft.engine.spec.params import check_param_values

    check_param_values(spec, {name: [value] for name, value in options.params.items()}, "--param")
    record, passive, interceptor = options.record, options.mode == RunMode.PASSIVE, options.interceptor
    say(f"astaa-deft proxy: spec '{spec.name}', {'passive' if passive else 'star'} mode"
        + (f", recording to {record}" if record else "") + " — Ctrl-C to stop")
    places = [Place(path, option) for path, option in ((options.run_dir, "--run-dir"), (record, "--record")) if path]
    with writing(*places):
        outcome = run_bus(spec, options, duration)
    say(f"stopped ({outcome.end_reason}) after {outcome.seconds:.1f} s")
    for name, n in outcome.sent.items():
        # A recorder that did not finish never reported its counts: say so rather than "recorded 0".
        counted = ""
        if record:
            counted = f", recorded {outcome.recorded.get(name, 0)}" if outcome.complete else ", recorded ?"
        say(f"  {name:20} {n:8d} messages{counted}")
    if interceptor is not None:
        say(f"mutations applied: {outcome.mutations}")
        for line in untouched_policies(outcome.policies):
            say(line)
    if record:
        say(f"log: {record}  (astaa-deft log info {record})"
            + ("" if outcome.complete else " — incomplete: the recorder did not finish it"))
    for c in outcome.crashes:
        say(f"crashed: {c.describe()}")
    return exit_code(outcome)


def exit_code(outcome: RunResult) -> int:
    """Print the verdict (or why there is none) and pick the exit code: 0 Pass, 1 a finding, 3 not observed."""
    from astaa_deft.engine.monitor.verdict import format_verdict

    if not outcome.complete or not outcome.observed:
        # Findings made before the loss are real, but a Pass would claim what nobody saw.
        if outcome.verdict is not None and outcome.verdict.klass != Verdict.PASS:
            say(format_verdict(outcome.verdict))
        why = outcome.end_reason if not outcome.observed or "recorder" in outcome.end_reason \
            else "the recorder did not finish the log"
        say(f"verdict withheld: the run was not fully observed ({why})")
        return EXIT_NOT_OBSERVED
    if outcome.verdict is not None and outcome.unjudged and outcome.verdict.klass == Verdict.PASS:
        say(f"verdict withheld: not every message was judged ({outcome.unjudged})")  # a Pass nobody fully saw
        return EXIT_NOT_OBSERVED
    if outcome.verdict is not None:
        say(format_verdict(outcome.verdict))
        return 0 if outcome.verdict.klass == Verdict.PASS else 1
    return 1 if outcome.crashes else 0
