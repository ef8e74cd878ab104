"""The run loop: the one place where a run of the SUT is started, watched and ended."""

from __future__ import annotations

import time
from collections.abc import Callable

from astaa_deft.io.log import records as rec
from astaa_deft.model.sut import Spec
from astaa_deft.engine.session.bus_run import BusRun
from astaa_deft.engine.session.options import RunOptions, RunResult
from astaa_deft.engine.session.run_end import RunEndWatch
from astaa_deft.engine.session.view import RunView

POLL_SECONDS = 0.05


def run_session(spec: Spec, options: RunOptions, *,
                stop_when: Callable[[RunView], str | None] | None = None,
                on_event: Callable[[rec.Record], None] | None = None,
                on_start: Callable[[RunView], None] | None = None) -> RunResult:
    """Run the SUT of ``spec`` once through the bus and return what happened.

    Stable entry point for commands, minimisation, campaigns and benchmarks.

    * ``spec``: a loaded :class:`~astaa_deft.model.sut.Spec`.
    * ``options``: :class:`RunOptions` (mode, recording path, params, run dir,
      interceptor, time limit, ...). Each call has its own tool session,
      helper processes and run directory (a fresh temp dir unless
      ``options.run_dir`` is given), so concurrent calls in one process do
      not share state; give each its own ``run_dir`` and log path, and port 0
      (the default) in ``zenoh.endpoints``.
    * ``stop_when(view)``: polled every 50 ms while the run goes on (``view``:
      a :class:`~astaa_deft.engine.session.view.RunView`); a non-empty
      string ends the run and becomes its ``end_reason``.
    * ``on_event(record)``: every event as a typed record
      (:mod:`astaa_deft.io.log.records`), from the thread that produced it —
      keep it quick and thread-safe.
    * ``on_start(view)``: called once the modules are launched (e.g. to
      subscribe to a channel with ``view.subscribe``).

    The run ends at the first of: the recorder or the bus router lost (then
    ``complete``/``observed`` is False); ``options.time_limit`` or the spec's
    ``run: time_limit``; a violation with ``options.stop_on_violation``; a
    condition of the spec's ``run: end_when`` (a module's exit, an expression
    over a channel's latest message); a module's abnormal exit the spec does
    not declare as an outcome (unless it says ``on_crash: keep_running`` for
    that module); every launched module gone; ``stop_when``. An end the spec
    declares as a failure (an exit code or a condition with a ``crash``
    class) is a finding of the run's verdict.
    Raises :class:`~astaa_deft.model.errors.InputError` when the run cannot start.
    """
    run = BusRun(spec, options, on_event=on_event)
    view = RunView(run)
    ends = RunEndWatch(spec, options.shutdown_delays)
    time_limit = min((t for t in (options.time_limit, ends.time_limit) if t is not None), default=None)
    t0 = time.monotonic()
    with run:
        t0 = time.monotonic()
        ends.attach(view)
        if ends.section.module_exits:
            run.hold_judgement(ends.judged_until)
        if on_start is not None:
            on_start(view)
        while True:
            reason = _why_end(run, view, ends, t0=t0, time_limit=time_limit, stop_when=stop_when)
            if reason:
                break
            time.sleep(POLL_SECONDS)
        seconds = time.monotonic() - t0
        sent = run.counts()
        by_spec = ends.ended if ends.ended is not None and ends.ended.reason == reason else None
        finding = by_spec.finding() if by_spec is not None else None
        if finding is not None:
            run.add_finding(finding)
        run.end(reason, by_spec.time_ns if by_spec is not None else None)  # dated when it happened
    verdict = run.judge.verdict if run.judge is not None else None
    monitor_set = run.judge.monitor_set if run.judge is not None else None
    # messages the monitors could not read, a monitor switched off: not fully observed, no Pass
    unjudged = monitor_set.unjudged() if monitor_set is not None and verdict is not None else ""
    recorder = run.recorder
    return RunResult(
        end_reason=reason, seconds=seconds, verdict=verdict, violations=tuple(run.violations),
        exits=tuple(run.exits), sent=sent, recorded=dict(recorder.recorded) if recorder is not None else {},
        mutations=run.mutations, log=options.record,
        complete=options.record is None or (recorder is not None and recorder.finished),
        observed=verdict is not None and not run.lost, unjudged=unjudged,
        policies=tuple(run.transport.policies) if run.transport is not None else (), shutdowns=ends.shutdowns())


def _why_end(run: BusRun, view: RunView, ends: RunEndWatch, *, t0: float, time_limit: float | None,
             stop_when: Callable[[RunView], str | None] | None) -> str:
    """Why the run ends now ("" while it goes on): the first that holds of the conditions ``run_session`` lists."""
    lost = run.helper_lost()
    if lost:
        return lost
    if time_limit is not None and time.monotonic() - t0 >= time_limit:
        return "time limit"
    if run.judge is not None and run.judge.stop_requested.is_set():
        return "violation (--stop-on-violation)"
    ended = ends.check(list(run.exits))
    if ended is not None:
        return ended.reason
    ending = {m.name for m in run.spec.modules if m.on_crash == "end_run"}
    crash = next((e for e in run.crashed() if e.module in ending), None)
    if crash is not None:
        # The verdict is decided (Abort at least); going on would only wait for a time limit or a Ctrl-C.
        return f"{crash.describe()} (on_crash: end_run)"
    if run.modules is not None and not run.alive():
        return "all modules exited"
    if stop_when is not None:
        return stop_when(view) or ""
    return ""
