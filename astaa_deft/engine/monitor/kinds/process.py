"""``process``: modules keep running — no exit, no kill by a signal, no restart.

    - {name: control_alive, kind: process, modules: [control]}
    - {name: stack_alive, kind: process}                     # every module
    - {name: planner_no_restart, kind: process, modules: [planning], restart_counter: header.seq}

An exit during the run's own shutdown is not a violation. A module that
exits with code 0 mid-run is one too (it stopped serving), unless
``allow_clean_exit: true``; it points at *Hindering* on the CRASH scale
(it reports success for a failure), a non-zero code or a signal at *Abort*.

A module may be restarted behind the launcher's back (a wrapper script, a
supervisor, a respawning launch file): the launcher then sees nothing.
``restart_counter`` names a counter every message of the module's channels
carries (a header sequence number); when it goes backwards, the producer
started over. That points at *Restart*.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from astaa_deft.model.records import ProcessExit, Verdict
from astaa_deft.model.fields import FieldPath, FieldPathError, type_at
from astaa_deft.io.yamlsource import Node
from astaa_deft.engine.monitor.base import ReplayJudges, NO_VIOLATIONS, Invariant, Monitor, MonitorContext
from astaa_deft.engine.monitor.error_signature import signature_of_output
from astaa_deft.engine.monitor.expression import RUNTIME_ERRORS, follow
from astaa_deft.engine.monitor.paths import is_number
from astaa_deft.engine.monitor.spec_reader import InvariantReader
from astaa_deft.engine.monitor.violation import Violation
from astaa_deft.engine.monitor.kinds import Kind

KEYS = ("modules", "allow_clean_exit", "restart_counter")
REQUIRED = ()


@dataclass(frozen=True, kw_only=True)
class ProcessInvariant(Invariant):
    kind: ClassVar[str] = "process"
    replay_judges: ClassVar[ReplayJudges] = ReplayJudges.PROCESS
    crash_kind: ClassVar[bool] = True
    default_crash: ClassVar[Verdict] = Verdict.ABORT

    modules: tuple[str, ...]
    allow_clean_exit: bool = False
    restart_counter: FieldPath | None = None
    counter_channels: tuple[str, ...] = ()  # the watched modules' channels whose type has the counter


def parse(reader: InvariantReader, node: Node, common: dict) -> ProcessInvariant | None:
    v = node.value
    modules = reader.module_list(v.get("modules"), "control")
    if modules is None:
        return None
    allow_clean = bool(reader.boolean(v.get("allow_clean_exit"), "'allow_clean_exit'"))
    counter, counter_channels = None, []
    if "restart_counter" in v:
        cnode = v["restart_counter"]
        text = reader.text(cnode, "'restart_counter'", "header.seq")
        if text is None:
            return None
        produced = [c for c in reader.channels.values() if c.producer in modules]
        for channel in produced:
            found = _silent_field(reader, channel.type, text)
            if found is not None:
                counter = found
                counter_channels.append(channel.name)
        if not counter_channels:
            reader.problem(cnode, f"no channel produced by {', '.join(modules)} has a numeric field '{text}'",
                           "name a counter field (e.g. header.seq) of a message type those modules publish")
            return None
    return ProcessInvariant(modules=modules, allow_clean_exit=allow_clean, restart_counter=counter,
                            counter_channels=tuple(counter_channels), **common)


def _silent_field(reader: InvariantReader, type_name: str, text: str) -> FieldPath | None:
    """The path if ``type_name`` has it as a number; no problem reported (other channels may have it)."""
    try:
        path = FieldPath.parse(text)
        declared = type_at(reader.types, type_name, path)
    except (FieldPathError, KeyError):
        return None
    if declared.kind in ("struct", "array", "enum", "string", "bytes", "bool") or not path.is_concrete:
        return None
    return path


class ProcessMonitor(Monitor):
    def __init__(self, invariant: ProcessInvariant, context: MonitorContext):
        super().__init__(invariant, context)
        self.inv = invariant
        self._last_counter: dict[str, float] = {}
        self._counter_segments = invariant.restart_counter.segments if invariant.restart_counter else ()

    def channels(self) -> set[str]:
        return set(self.inv.counter_channels)

    def on_process_exit(self, exit_: ProcessExit) -> list[Violation]:
        if exit_.module not in self.inv.modules or exit_.during_shutdown:
            return NO_VIOLATIONS
        self.evaluations += 1
        clean = exit_.returncode == 0 and exit_.signal is None
        if clean and self.inv.allow_clean_exit:
            return NO_VIOLATIONS
        self.violating += 1
        detail = f"{exit_.as_finding()} during the run"
        if clean:
            detail += " (a clean exit code for a module that stopped serving)"
        tail = exit_.stderr_tail.strip().splitlines()[-5:]
        context = {"returncode": exit_.returncode, "signal": exit_.signal, "stderr_tail": "\n".join(tail)}
        said = signature_of_output(exit_.stderr_tail.splitlines(), exit_.signal)
        if said is not None:  # which error it died of: the last traceback or panic of its output, or the signal
            context["signature"] = said.text()
        return [self.violation(exit_.time_ns, detail, module=exit_.module, message=context,
                               crash=Verdict.HINDERING if clean else Verdict.ABORT)]

    def on_message(self, channel: str, time_ns: int, value: dict | None, seq: int) -> list[Violation]:
        if value is None:
            return NO_VIOLATIONS
        try:
            counter = follow(value, self._counter_segments)
        except RUNTIME_ERRORS:
            return NO_VIOLATIONS  # a missing counter is a bound invariant's business
        if not is_number(counter):
            return NO_VIOLATIONS
        self.evaluations += 1
        previous = self._last_counter.get(channel)
        self._last_counter[channel] = counter
        if previous is None or counter >= previous:
            return NO_VIOLATIONS
        self.violating += 1
        producer = self.context.producer(channel)
        detail = (f"module '{producer}' restarted: {self.inv.restart_counter} on '{channel}' went back "
                  f"from {previous:g} to {counter:g}")
        return [self.violation(time_ns, detail, channel=channel, seq=seq, message=value, crash=Verdict.RESTART)]


def monitor(invariant: ProcessInvariant, context: MonitorContext) -> ProcessMonitor:
    return ProcessMonitor(invariant, context)


Kind.register(ProcessInvariant, KEYS, REQUIRED, parse=parse, monitor=monitor)
