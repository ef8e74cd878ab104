"""A broken invariant, as printed on the console and stored in the log.

A violation names the moment the invariant broke and the message that broke
it. Monitors report one violation per *episode*: the first message that
breaks an invariant after it held (or since the start); the messages that
keep it broken are counted, not reported again, so a NaN stream at 100 Hz
yields one line, not a hundred.
"""

from __future__ import annotations

import base64
import math
from dataclasses import dataclass
from typing import Any
from collections.abc import Mapping

# The CRASH class a violation points at when nothing overrides it (see verdict.py).
CRASH_CLASSES = ("Catastrophic", "Restart", "Abort", "Silent", "Hindering")
SEVERITIES = ("low", "medium", "high", "critical")
RUN_END_KIND = "run_end"  # a finding made by the spec's run: section (a failing exit code or end condition)

# Bounds on the copy of the offending message kept in a violation: the log
# should show the culprit, not grow by a 200-point trajectory per violation.
MAX_ITEMS = 20
MAX_TEXT = 200
MAX_DEPTH = 6


@dataclass(frozen=True)
class Violation:
    invariant: str
    kind: str
    severity: str
    time_ns: int  # when the invariant broke (the message's time, or the deadline that expired)
    channel: str | None
    seq: int | None  # 1-based index of the message on its channel, as the recorder numbers it
    message: dict | None  # the offending message (truncated, JSON-safe), or context for kinds without one
    detail: str
    crash: str = "Silent"  # the CRASH class this violation points at
    module: str | None = None  # the module held responsible, when one is

    def to_json(self) -> dict:
        return {
            "invariant": self.invariant, "invariant_kind": self.kind, "severity": self.severity,
            "time_ns": self.time_ns, "channel": self.channel, "seq": self.seq, "message": self.message,
            "detail": self.detail, "crash": self.crash, "module": self.module,
        }

    @classmethod
    def from_json(cls, body: Mapping[str, Any]) -> Violation:
        return cls(
            invariant=str(body.get("invariant", "?")), kind=str(body.get("invariant_kind", "?")),
            severity=str(body.get("severity", "high")), time_ns=int(body.get("time_ns", 0)),
            channel=body.get("channel"), seq=body.get("seq"), message=body.get("message"),
            detail=str(body.get("detail", "")), crash=str(body.get("crash", "Silent")), module=body.get("module"),
        )

    @property
    def where(self) -> str:
        """'on trajectory #12', 'module control', or ''."""
        if self.channel is not None:
            return f"on '{self.channel}'" + (f" #{self.seq}" if self.seq is not None else "")
        if self.module is not None:
            return f"module '{self.module}'"
        return ""


def format_violation(v: Violation, start_ns: int | None = None) -> str:
    """One console line: '!! [high] speed_limit (expression) on 'status' #37 at +12.300 s: ...'."""
    when = f" at +{(v.time_ns - start_ns) / 1e9:.3f} s" if start_ns is not None else ""
    where = f" {v.where}" if v.where else ""
    return f"!! [{v.severity}] {v.invariant} ({v.kind}){where}{when}: {v.detail}"


def json_safe(value: Any, depth: int = 0) -> Any:
    """A bounded, JSON-safe copy of plain message data.

    Non-finite floats become the strings "NaN", "Infinity", "-Infinity"
    (strict JSON has no such numbers), bytes become base64, and long arrays,
    long strings and deep nesting are cut with a marker saying so.
    """
    if isinstance(value, float):
        if math.isfinite(value):
            return value
        return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")
    if value is None or isinstance(value, (bool, int)):
        return value
    if isinstance(value, str):
        return value if len(value) <= MAX_TEXT else value[:MAX_TEXT] + f"…(+{len(value) - MAX_TEXT} chars)"
    if isinstance(value, (bytes, bytearray)):
        shown = base64.b64encode(bytes(value[:MAX_TEXT])).decode()
        return {"$bytes": shown, "length": len(value)}
    if depth >= MAX_DEPTH:
        return "…(nested deeper)"
    if isinstance(value, dict):
        items = list(value.items())
        out = {str(k): json_safe(v, depth + 1) for k, v in items[:MAX_ITEMS]}
        if len(items) > MAX_ITEMS:
            out["…"] = f"{len(items) - MAX_ITEMS} more fields"
        return out
    if isinstance(value, (list, tuple)):
        out_list = [json_safe(v, depth + 1) for v in value[:MAX_ITEMS]]
        if len(value) > MAX_ITEMS:
            out_list.append(f"…({len(value) - MAX_ITEMS} more items)")
        return out_list
    return repr(value)[:MAX_TEXT]


def message_copy(value: Any) -> dict | None:
    """The offending message as stored in a violation."""
    if value is None:
        return None
    safe = json_safe(value)
    return safe if isinstance(safe, dict) else {"value": safe}
