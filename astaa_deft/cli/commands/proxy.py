"""`astaa-deft proxy`: run the SUT through the star (or watch it passively) and record it."""

from __future__ import annotations

import time
from pathlib import Path
from collections.abc import Callable

from astaa_deft.io.log import records as rec
from astaa_deft.io.output_place import Place, writing
from astaa_deft.engine.session import RunOptions, RunResult, RunView, run_session
from astaa_deft.engine.session.summary import untouched_policies
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.params import check_param_values
from astaa_deft.engine.monitor.verdict import format_verdict
from astaa_deft.cli.commands.console import RateMeter, StatusLine, StopSignal, format_event, say


MUTATIONS_SHOWN = 3
EXIT_NOT_OBSERVED = 3  # the tool lost its recorder or bus router: no verdict can be given


def run_bus(spec: Spec, options: RunOptions, duration: float | None,
            until: Callable[[RunView], str | None] = lambda run: None,
            on_start: Callable[[RunView], None] = lambda run: None, verbose: bool = True) -> RunResult:
    """:func:`run_session` with the console: events as they come, a status line, Ctrl-C/SIGTERM to stop."""

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
        options.time_limit = duration if options.time_limit is None else min(duration, options.time_limit)
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


def run(spec: Spec, record: Path | None, passive: bool, duration: float | None, launch: bool,
        params: dict[str, str], command_line: list[str], run_dir: Path | None,
        stop_on_violation: bool = False, interceptor=None, attachments: dict | None = None) -> int:
    check_param_values(spec, {name: [value] for name, value in params.items()}, "--param")
    options = RunOptions(mode="passive" if passive else "star", launch=launch, record=record, params=params,
                         command_line=command_line, run_dir=run_dir, stop_on_violation=stop_on_violation,
                         interceptor=interceptor, attachments=attachments or {})
    say(f"astaa-deft proxy: spec '{spec.name}', {'passive' if passive else 'star'} mode"
        + (f", recording to {record}" if record else "") + " — Ctrl-C to stop")
    places = [Place(path, option) for path, option in ((run_dir, "--run-dir"), (record, "--record")) if path]
    with writing(*places):
        outcome = run_bus(spec, options, duration)
    say(f"stopped ({outcome.end_reason}) after {outcome.seconds:.1f} s")
    for name, n in outcome.sent.items():
        # A recorder that did not finish never reported its counts: say so rather than "recorded 0".
        rec = (f", recorded {outcome.recorded.get(name, 0)}" if outcome.complete else ", recorded ?") if record else ""
        say(f"  {name:20} {n:8d} messages{rec}")
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
    if not outcome.complete or not outcome.observed:
        # Findings made before the loss are real, but a Pass would claim what nobody saw.
        if outcome.verdict is not None and outcome.verdict.klass != "Pass":
            say(format_verdict(outcome.verdict))
        why = outcome.end_reason if not outcome.observed or "recorder" in outcome.end_reason \
            else "the recorder did not finish the log"
        say(f"verdict withheld: the run was not fully observed ({why})")
        return EXIT_NOT_OBSERVED
    if outcome.verdict is not None:
        say(format_verdict(outcome.verdict))
        return 0 if outcome.verdict.klass == "Pass" else 1
    return 1 if outcome.crashes else 0
