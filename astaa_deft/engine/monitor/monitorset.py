"""All of a spec's invariants, evaluated together over one run.

The same object serves both sides:

* online, the tool feeds it what it sees on the bus (time = receive time),
  the launcher's process exits, and a clock tick about every 50 ms;
* offline (``offline.check_log``), the log's messages in log-time order,
  its process-exit events, a tick at every message time, and the end.

Monitors only ever use the times they are given, and a violation is dated
by the message (or expired deadline) that caused it, never by when it was
noticed; small differences between the tool's and the recorder's receive
times therefore do not change verdicts.

Calls may come from several threads (bus callbacks, the tick timer): one
lock serialises them. A monitor that raises (a bug) is switched off with a
warning instead of ending the run.

What a monitor could not judge is counted, never skipped in silence: a
message whose payload does not decode, on a channel of a monitor that
cannot read it (``Monitor.judges_undecodable`` False: collision, temporal,
process counters), and every message after a monitor was switched off.
``unjudged()`` says so; a run with any is not fully observed, so its Pass
is withheld (``check`` exits 3, ``proxy`` says "verdict withheld").
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from astaa_deft.model.sut import Spec
from astaa_deft.engine.monitor.base import LogLineInfo, Monitor, MonitorContext
from astaa_deft.engine.monitor.invariants import with_typed_invariants
from astaa_deft.engine.monitor.kinds import KINDS
from astaa_deft.engine.monitor.verdict import RunVerdict, run_verdict
from astaa_deft.model.records import ProcessExit
from astaa_deft.engine.monitor.violation import Violation


class MonitorSet:
    def __init__(self, spec: Spec, start_ns: int):
        spec = with_typed_invariants(spec)
        self.spec = spec
        self.start_ns = start_ns
        context = MonitorContext(spec, start_ns)
        self.monitors: list[Monitor] = [KINDS[inv.kind].monitor(inv, context) for inv in spec.invariants]
        self._routes: dict[str, list[Monitor]] = {}
        for monitor in self.monitors:
            for channel in monitor.channels():
                self._routes.setdefault(channel, []).append(monitor)
        self._tickers = [m for m in self.monitors if m.wants_ticks]
        self._log_readers = [m for m in self.monitors if m.wants_log_lines]
        self.violations: list[Violation] = []
        self.exits: list[ProcessExit] = []  # for the run verdict
        self.warnings: list[str] = []
        self.messages = 0
        self.undecodable: dict[str, int] = {}  # invariant → messages on its channels it could not read
        self.switched_off: list[str] = []  # invariants whose monitor raised and was switched off
        self._lock = threading.Lock()
        self._finished = False

    # -- what the lead decodes -----------------------------------------------
    def channels(self) -> set[str]:
        """Names of the channels any invariant reads (others need not be decoded or passed in)."""
        return set(self._routes)

    # -- inputs --------------------------------------------------------------
    def on_message(self, channel: str, time_ns: int, value: dict | None, seq: int) -> list[Violation]:
        monitors = self._routes.get(channel)
        if not monitors:
            return []
        with self._lock:
            self.messages += 1
            if value is None:
                for monitor in monitors:
                    if not monitor.judges_undecodable:
                        name = monitor.invariant.name
                        self.undecodable[name] = self.undecodable.get(name, 0) + 1
            return self._collect(monitors, lambda m: m.on_message(channel, time_ns, value, seq))

    def on_process_exit(self, module: str, returncode: int, signal: str | None, time_ns: int, *,
                        during_shutdown: bool, stderr_tail: str = "") -> list[Violation]:
        # pid 0: monitors judge a module's exit, never its process id (the log keeps the real one).
        exit_ = ProcessExit(module=module, pid=0, returncode=returncode, signal=signal, time_ns=time_ns,
                            during_shutdown=during_shutdown, stderr_tail=stderr_tail)
        with self._lock:
            self.exits.append(exit_)
            return self._collect(self.monitors, lambda m: m.on_process_exit(exit_))

    def wants_log_lines(self) -> bool:
        return bool(self._log_readers)

    def on_log_line(self, module: str, text: str, time_ns: int) -> list[Violation]:
        if not self._log_readers:
            return []
        line = LogLineInfo(module, text, time_ns)
        with self._lock:
            return self._collect(self._log_readers, lambda m: m.on_log_line(line))

    def on_tick(self, time_ns: int) -> list[Violation]:
        if not self._tickers:
            return []
        with self._lock:
            return self._collect(self._tickers, lambda m: m.on_tick(time_ns))

    def finish(self, time_ns: int) -> list[Violation]:
        """The run ended at ``time_ns``: report what only the end decides. Later calls do nothing."""
        with self._lock:
            if self._finished:
                return []
            self._finished = True
            return self._collect(self.monitors, lambda m: m.finish(time_ns))

    def add_finding(self, violation: Violation) -> None:
        """A finding made outside the monitors (a run's declared outcome), counted in the verdict."""
        with self._lock:
            self.violations.append(violation)

    # -- results -------------------------------------------------------------
    def verdict(self, *, bus_lost: bool = False) -> RunVerdict:
        """The run's CRASH verdict from everything seen so far (``bus_lost``: the log says the bus was lost)."""
        with self._lock:
            return run_verdict(self.violations, self.exits, [m.name for m in self.spec.modules], bus_lost=bus_lost)

    def unjudged(self) -> str:
        """Why the monitors did not judge the whole run ("" when they did): messages they could not read,
        monitors switched off."""
        with self._lock:
            parts = [f"'{name}' could not read {n} message{'s' if n != 1 else ''} (the payload does not decode)"
                     for name, n in sorted(self.undecodable.items())]
            parts += [f"'{name}' failed and was switched off" for name in self.switched_off]
        return "; ".join(parts)

    def stats(self) -> dict[str, dict[str, int]]:
        """Per invariant: how many messages/samples were judged and how many broke it."""
        return {m.invariant.name: {"evaluations": m.evaluations, "violating": m.violating} for m in self.monitors}

    # -- internals -----------------------------------------------------------
    def _collect(self, monitors: list[Monitor], call: Callable[[Monitor], list[Violation]]) -> list[Violation]:
        found: list[Violation] = []
        broken: list[Monitor] = []
        for monitor in monitors:
            try:
                result = call(monitor)
            except Exception as exc:  # a bug in a monitor must not end the run under test
                broken.append(monitor)
                self.warnings.append(f"monitor '{monitor.invariant.name}' failed and was switched off: "
                                     f"{type(exc).__name__}: {exc}")
                continue
            if result:
                found.extend(result)
        if broken:
            self._switch_off(broken)
        if found:
            found.sort(key=lambda v: v.time_ns)
            self.violations.extend(found)
        return found

    def _switch_off(self, broken: list[Monitor]) -> None:
        self.switched_off.extend(m.invariant.name for m in broken)
        self.monitors = [m for m in self.monitors if m not in broken]
        self._tickers = [m for m in self._tickers if m not in broken]
        for channel, monitors in list(self._routes.items()):
            self._routes[channel] = [m for m in monitors if m not in broken]
