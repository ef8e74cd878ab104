"""The run's judge part: the online monitors, the findings as they come, and the CRASH-scale verdict."""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Callable

from astaa_deft.engine.bus import topology
from astaa_deft.engine.bus.launcher import ModuleNotReady
from astaa_deft.engine.monitor.monitorset import MonitorSet
from astaa_deft.engine.monitor.online import OnlineMonitors
from astaa_deft.engine.monitor.verdict import RunVerdict
from astaa_deft.model.records import ProcessExit, Verdict
from astaa_deft.engine.monitor.violation import Violation
from astaa_deft.engine.session.options import RunOptions
from astaa_deft.engine.session.parts import EventLog, RunPart, ToolSession
from astaa_deft.engine.session.transport import Transport
from astaa_deft.io.log import records as rec
from astaa_deft.model.sut import Spec


class Judge(RunPart):
    """Says in the log that the run started, judges every message, and gives the verdict at ``stopping``.

    Findings may arrive from any thread (monitors, the launcher's watcher,
    the run loop); ``violations`` only grows. ``verdict`` is None until the
    run stopped with its monitors running.
    """

    def __init__(self, spec: Spec, options: RunOptions, *, session: ToolSession, transport: Transport,
                 events: EventLog):
        self._spec, self._options, self._session, self._transport = spec, options, session, transport
        self._events = events
        self.monitors: OnlineMonitors | None = None  # while judging
        self.monitor_set: MonitorSet | None = None  # the monitors' state, kept after the verdict
        self.verdict: RunVerdict | None = None
        self.violations: list[Violation] = []
        self.stop_requested = threading.Event()  # --stop-on-violation
        self._judged_until_ns = 2**63  # set when the run begins to stop

    def start(self) -> None:
        opts = self._options
        started = self._events.emit(rec.RunStarted(time_ns=time.time_ns(), mode=opts.mode, spec=self._spec.name,
                                                   command_line=tuple(opts.command_line),
                                                   interceptor_epoch_ns=self._transport.interceptor_epoch_ns))
        self.monitors = OnlineMonitors(self._spec, started.time_ns, self._violated)
        self.monitor_set = self.monitors.set
        intercepted = self._transport.intercepted
        self.monitors.subscribe(self._session.session,
                                [(k, ch.name) for k, ch in topology.observed_keys(self._spec, opts.mode)
                                 if ch.name not in intercepted])
        if self._transport.interception is not None:
            self._transport.interception.on_delivered = self.monitors.feed

    def stopping(self) -> None:
        if self.monitors is None:
            self._judged_until_ns = time.time_ns()
            return
        stopping = self._events.emit(rec.RunStopping(time.time_ns()))
        self._judged_until_ns = stopping.time_ns
        # Judged up to the stop, as `check` judges the log: the silence of modules being stopped
        # (one slow to exit, a loaded machine) is the tool's doing, not a hang of the SUT.
        self.verdict = self.monitors.finish(stopping.time_ns)  # None: the monitors fell behind, no verdict
        if self.verdict is not None:
            self._events.emit(dataclasses.replace(self.verdict, time_ns=time.time_ns()))
        self.monitors = None

    def end(self, reason: str, at_ns: int | None = None) -> None:
        """Say in the log why the run ends (before the modules are stopped); time is judged up to the end
        (``at_ns``: when it happened, if before now — an ending module's exit, a channel's message)."""
        now = time.time_ns()
        ended = self._events.emit(rec.RunEnd(now if at_ns is None else min(at_ns, now), reason))
        if self.monitors is not None:
            self.monitors.end_at(ended.time_ns)

    def hold(self, horizon: Callable[[int], int]) -> None:
        """Judge no further than ``horizon(now)`` until the end: the end cannot come before it."""
        if self.monitors is not None:
            self.monitors.horizon = horizon

    def add_finding(self, violation: Violation) -> None:
        """A finding made outside the monitors (the spec's run: outcome): in the verdict and the log."""
        if self.monitors is not None:
            self.monitors.set.add_finding(violation)
        self._violated(violation)

    def not_ready(self, exc: ModuleNotReady) -> None:
        """A module alive but silent at its start: a hang as far as the CRASH scale goes (no Pass)."""
        if self.monitors is None:
            return
        found = Violation(invariant="(module start)", invariant_kind="ready", severity="high", time_ns=time.time_ns(),
                          channel=None, seq=None, message=None, detail=f"module '{exc.module}' not ready: {exc.detail}",
                          crash=Verdict.RESTART, module=exc.module)
        self.monitors.set.violations.append(found)  # the verdict is the monitors' own: they must count it
        self._violated(found)

    def module_line(self, module: str, text: str, time_ns: int) -> None:
        """A line a module wrote: judged if the monitors read lines and the run had not begun to stop."""
        monitors = self.monitors
        # Lines read after the run began to stop are logged, not judged (offline, `check` does the same).
        if monitors is not None and monitors.wants_log_lines() and time_ns <= self._judged_until_ns:
            monitors.log_line(module, text, time_ns)

    def process_exit(self, exit_: ProcessExit) -> None:
        """A module's exit, for the monitors (an abnormal one is a finding)."""
        if self.monitors is not None:
            self.monitors.process_exit(exit_.module, exit_.returncode, exit_.signal, exit_.time_ns,
                                       during_shutdown=exit_.during_shutdown, stderr_tail=exit_.stderr_tail)

    def _violated(self, violation: Violation) -> None:
        self.violations.append(violation)
        self._events.emit(violation)
        if self._options.stop_on_violation:
            self.stop_requested.set()
