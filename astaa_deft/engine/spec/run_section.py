"""The spec's ``run:`` section: how a run of the SUT ends, and what its end means.

    run:
      time_limit: 60                       # seconds from the modules' launch
      end_when:
        - module: simulator                # the run ends when this module exits …
          exit_codes:                      # … and its exit code is the run's outcome
            - {code: 0, outcome: pass}
            - {code: 1, outcome: collision, crash: Silent, severity: critical}
            - {code: 2, outcome: goal_not_reached}     # crash Silent, severity high unless given
            # - {code: other, outcome: crashed, crash: Abort}   (codes not listed: the default)
          shutdown_delay: 3                # optional: seconds its exit may come after its last message
        - {channel: status, expr: "done", reason: done}   # … or when a channel's latest message says so
        - {channel: status, expr: "collision", reason: collision, crash: Silent, severity: critical}

The conditions are generic (no SUT-specific code): every caller of
:func:`astaa_deft.engine.session.run_session` gets them. Pure parsing: no I/O, no
Zenoh. Expressions are the monitors' safe expression language, type-checked
against the channel's declared message type when the spec is loaded.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from astaa_deft.engine.monitor.spec_reader import InvariantReader
from astaa_deft.engine.monitor.violation import CRASH_CLASSES, SEVERITIES
from astaa_deft.io.yamlsource import Node, Source, describe_value
from astaa_deft.model.records import Verdict
from astaa_deft.model.sut import Channel, MessageType
from astaa_deft.model.run_section import (
    CRASHED, DEFAULT_SEVERITY, PASS, PASS_OUTCOME, ChannelEnd, ModuleExitEnd, Outcome, RunSection,
)

KEYS = ("time_limit", "end_when")
MODULE_KEYS = ("module", "exit_codes", "reason", "shutdown_delay")
CHANNEL_KEYS = ("channel", "expr", "reason", "crash", "severity")
CODE_KEYS = ("code", "outcome", "crash", "severity")
DEFAULT_FAILURE_CRASH = Verdict.SILENT  # a named outcome the module reports: the SUT noticed nothing else
MAX_TIME_LIMIT = 7 * 24 * 3600.0
MAX_SHUTDOWN_DELAY = 3600.0  # an exit an hour after the last message is no shutdown but a hang


def build_run_section(src: Source, node: Node | None, types: Mapping[str, MessageType],
                      channels: Sequence[Channel], *, modules: Sequence[str]) -> RunSection:
    """The ``run:`` section, or an empty one; every problem reported to ``src`` with its place and a fix."""
    if node is None or node.value is None:
        return RunSection()
    reader = InvariantReader(src, types, channels, modules)
    if not reader.keys(node, KEYS, (), "'run'"):
        return RunSection()
    v = node.value
    time_limit = reader.number(v.get("time_limit"), "'time_limit'", positive=True)
    if time_limit is not None and time_limit > MAX_TIME_LIMIT:
        reader.problem(v["time_limit"], f"'time_limit' of {time_limit:g} s is more than a week",
                       "give the run's limit in seconds, e.g. time_limit: 60")
        time_limit = None
    module_exits: list[ModuleExitEnd] = []
    channel_ends: list[ChannelEnd] = []
    ends = v.get("end_when")
    if ends is not None:
        if not ends.is_list or not ends.value:
            reader.problem(ends, "'end_when' must be a non-empty list of conditions",
                           "e.g. end_when: [{module: simulator}, {channel: status, expr: \"done\", reason: done}]")
        else:
            for item in ends.value:
                _condition(reader, item, module_exits, channel_ends)
    return RunSection(time_limit, tuple(module_exits), tuple(channel_ends))


def _condition(reader: InvariantReader, item: Node, module_exits: list, channel_ends: list) -> None:
    if not item.is_map or not ("module" in item.value) ^ ("channel" in item.value):
        reader.problem(item, "each 'end_when' condition names either a 'module' (its exit ends the run) "
                             "or a 'channel' with an 'expr'",
                       "e.g. - {module: simulator} or - {channel: status, expr: \"done\", reason: done}")
        return
    v = item.value
    if "module" in v:
        if not reader.keys(item, MODULE_KEYS, ("module",), "an 'end_when' module condition"):
            return
        module = reader.module(v["module"])
        codes, other = _exit_codes(reader, v.get("exit_codes"))
        reason = _reason(reader, v.get("reason")) if "reason" in v else ""
        delay, delay_ok = _shutdown_delay(reader, v.get("shutdown_delay"))
        if module is not None and any(m.module == module for m in module_exits):
            reader.problem(v["module"], f"module '{module}' is named twice under 'run: end_when'",
                           "keep one condition per module")
            return
        if module is not None and codes is not None and reason is not None and delay_ok:
            module_exits.append(ModuleExitEnd(module=module, exit_codes=codes, other=other, reason=reason,
                                              shutdown_delay=delay))
        return
    if not reader.keys(item, CHANNEL_KEYS, ("channel", "expr", "reason"), "an 'end_when' channel condition"):
        return
    channel = reader.channel(v["channel"])
    reason = _reason(reader, v["reason"])
    outcome = _failure(reader, item, reason or "?") if ("crash" in v or "severity" in v) else PASS_OUTCOME
    if channel is None:
        return
    expr = reader.expression(v["expr"], channel.type, "'expr'")
    if expr is not None and reason is not None and outcome is not None:
        channel_ends.append(ChannelEnd(channel.name, expr, reason, outcome))


def _shutdown_delay(reader: InvariantReader, node: Node | None) -> tuple[float | None, bool]:
    """The module's ``shutdown_delay`` in seconds (None: not given) and whether it was read without a problem."""
    if node is None:
        return None, True
    delay = reader.number(node, "'shutdown_delay'", positive=True, maximum=MAX_SHUTDOWN_DELAY)
    return delay, delay is not None


def _reason(reader: InvariantReader, node: Node) -> str | None:
    return reader.text(node, "'reason'", "goal_reached")


def _exit_codes(reader: InvariantReader, node: Node | None) -> tuple[dict[int, Outcome] | None, Outcome]:
    if node is None:
        return {0: PASS_OUTCOME}, CRASHED
    if not node.is_list or not node.value:
        reader.problem(node, "'exit_codes' must be a list of {code: …, outcome: …}",
                       "e.g. exit_codes: [{code: 0, outcome: pass}, {code: 1, outcome: collision, crash: Silent}]")
        return None, CRASHED
    codes: dict[int, Outcome] = {}
    other = CRASHED
    ok = True
    for item in node.value:
        if not reader.keys(item, CODE_KEYS, ("code", "outcome"), "an exit code's outcome"):
            ok = False
            continue
        cnode = item.value["code"]
        code = cnode.value
        if code != "other" and (isinstance(code, bool) or not isinstance(code, int) or not 0 <= code <= 255):
            reader.problem(cnode, f"'code' must be a process exit code from 0 to 255 or 'other', "
                                  f"not {describe_value(code)}", "e.g. code: 1")
            ok = False
            continue
        if code in codes or (code == "other" and other is not CRASHED):
            reader.problem(cnode, f"exit code {code} is listed twice", "keep one outcome per code")
            ok = False
            continue
        found = _outcome(reader, item, f"code {code}")
        if found is None:
            ok = False
        elif code == "other":
            other = found
        else:
            codes[code] = found
    return (codes if ok else None), other


def _outcome(reader: InvariantReader, node: Node, name: str) -> Outcome | None:
    """``outcome: pass``, or a failure named by ``outcome`` (crash Silent and severity high unless given)."""
    text = reader.text(node.value["outcome"], "'outcome'", "collision")
    if text is None:
        return None
    if text.strip().lower() == PASS:
        if "crash" in node.value or "severity" in node.value:
            reader.problem(node, f"the outcome of {name} is 'pass': it has no 'crash' or 'severity'",
                           "remove them, or name the failure instead of 'pass'")
            return None
        return PASS_OUTCOME
    return _failure(reader, node, text.strip())


def _failure(reader: InvariantReader, node: Node, name: str) -> Outcome | None:
    v = node.value
    crash: Verdict | None = DEFAULT_FAILURE_CRASH
    if "crash" in v:
        text = v["crash"].value if isinstance(v["crash"].value, str) else ""
        crash = next((c for c in CRASH_CLASSES if c.lower() == text.lower()), None)
        if crash is None:
            reader.problem(v["crash"], f"'crash' must be one of {', '.join(CRASH_CLASSES)}, "
                                       f"not {describe_value(v['crash'].value)}",
                           "pick the CRASH class this end points at, e.g. crash: Silent")
    severity = reader.choice(v.get("severity"), "'severity'", SEVERITIES) if "severity" in v else DEFAULT_SEVERITY
    if crash is None or severity is None:
        return None
    return Outcome(name, crash, severity)
