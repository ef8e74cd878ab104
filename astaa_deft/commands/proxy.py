"""`astaa-deft proxy`: run the SUT through the star (or watch it passively) and record it."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..bus.run import BusRun, RunOptions
from ..spec.model import Spec
from ..monitor.verdict import format_verdict
from .console import RateMeter, StatusLine, StopSignal, format_event, say


MUTATIONS_SHOWN = 3


@dataclass
class Outcome:
    reason: str  # "duration", "signal", "all modules exited", "violation", "stopped"
    seconds: float
    counts: dict[str, int]
    recorded: dict[str, int]
    crashes: list
    verdict: object = None  # astaa_deft.monitor.verdict.Verdict
    violations: list = None
    mutations: int = 0


def run_bus(spec: Spec, options: RunOptions, duration: float | None,
            until: Callable[[BusRun], str | None] = lambda run: None,
            on_start: Callable[[BusRun], None] = lambda run: None, verbose: bool = True) -> Outcome:
    """Run until `duration`, Ctrl-C/SIGTERM, every module gone, or `until` names a reason."""

    shown: dict[str, int] = {}

    def on_event(event: dict) -> None:
        if event.get("kind") == "mutation":  # a policy may fire at 50 Hz: show the first few of each
            policy = str(event.get("policy"))
            shown[policy] = shown.get(policy, 0) + 1
            if shown[policy] > MUTATIONS_SHOWN:
                if shown[policy] == MUTATIONS_SHOWN + 1 and verbose:
                    say(f"~~ (further mutations of policy {policy} are in the log, not shown)")
                return
        text = format_event(event)
        if text and verbose:
            status.clear()
            say(text)

    with StopSignal() as stop:
        run = BusRun(spec, options, on_event=on_event)
        meter = RateMeter(run.counts)
        status = StatusLine(lambda: _status(run, meter, t0))
        t0 = time.monotonic()
        with run, status:
            t0 = time.monotonic()
            on_start(run)
            reason = "stopped"
            while True:
                time.sleep(0.05)
                if stop.requested():
                    reason = f"signal {stop.received}"
                    break
                if duration is not None and time.monotonic() - t0 >= duration:
                    reason = "duration"
                    break
                if run.stop_requested.is_set():
                    reason = "violation (--stop-on-violation)"
                    break
                if options.launch and run.launcher is not None and not run.alive():
                    reason = "all modules exited"
                    break
                custom = until(run)
                if custom:
                    reason = custom
                    break
            seconds = time.monotonic() - t0
            counts = run.counts()
        return Outcome(reason, seconds, counts, run.recorded, run.crashed(), run.verdict, run.violations,
                       run.interception.mutations if run.interception is not None else 0)


def _status(run: BusRun, meter: RateMeter, t0: float) -> str:
    rates = meter.rates()
    parts = [f"{name} {rate:.0f}/s" for name, rate in rates.items()]
    crashes = len(run.crashed())
    return f"[{time.monotonic() - t0:6.1f} s] " + " | ".join(parts) + (f" | crashes {crashes}" if crashes else "")


def run(spec: Spec, record: Path | None, passive: bool, duration: float | None, launch: bool,
        params: dict[str, str], command_line: list[str], run_dir: Path | None,
        stop_on_violation: bool = False, interceptor=None, attachments: dict | None = None) -> int:
    options = RunOptions(mode="passive" if passive else "star", launch=launch, record=record, params=params,
                         command_line=command_line, run_dir=run_dir, stop_on_violation=stop_on_violation,
                         interceptor=interceptor, attachments=attachments or {})
    say(f"astaa-deft proxy: spec '{spec.name}', {'passive' if passive else 'star'} mode"
        + (f", recording to {record}" if record else "") + " — Ctrl-C to stop")
    outcome = run_bus(spec, options, duration)
    say(f"stopped ({outcome.reason}) after {outcome.seconds:.1f} s")
    for name, n in outcome.counts.items():
        rec = f", recorded {outcome.recorded.get(name, 0)}" if record else ""
        say(f"  {name:20} {n:8d} messages{rec}")
    if interceptor is not None:
        say(f"mutations applied: {outcome.mutations}")
    if record:
        say(f"log: {record}  (astaa-deft log info {record})")
    for c in outcome.crashes:
        say(f"crashed: {c.describe()}")
    if outcome.verdict is not None:
        say(format_verdict(outcome.verdict))
        return 0 if outcome.verdict.klass == "Pass" else 1
    return 1 if outcome.crashes else 0
