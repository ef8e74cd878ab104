"""A broken invariant (``model.records.Violation``) as printed on the console, and its bounded message copy.

A violation names the moment the invariant broke and the message that broke
it. Monitors report one violation per *episode*: the first message that
breaks an invariant after it held (or since the start); the messages that
keep it broken are counted, not reported again, so a NaN stream at 100 Hz
yields one line, not a hundred.
"""

from __future__ import annotations

import base64
import math
from astaa_deft.model.json import JsonObject, JsonValue
from astaa_deft.model.records import CRASH_CLASSES, Violation

SEVERITIES = ("low", "medium", "high", "critical")
RUN_END_KIND = "run_end"  # a finding made by the spec's run: section (a failing exit code or end condition)

# Bounds on the copy of the offending message kept in a violation: the log
# should show the culprit, not grow by a 200-point trajectory per violation.
MAX_ITEMS = 20
MAX_TEXT = 200
MAX_DEPTH = 6

__all__ = ["CRASH_CLASSES", "MAX_DEPTH", "MAX_ITEMS", "MAX_TEXT", "RUN_END_KIND", "SEVERITIES", "Violation",
           "format_violation", "json_safe", "message_copy"]


def format_violation(v: Violation, start_ns: int | None = None) -> str:
    """One console line: '!! [high] speed_limit (expression) on 'status' #37 at +12.300 s: ...'."""
    when = f" at +{(v.time_ns - start_ns) / 1e9:.3f} s" if start_ns is not None else ""
    where = f" {v.where}" if v.where else ""
    return f"!! [{v.severity}] {v.invariant} ({v.invariant_kind}){where}{when}: {v.detail}"


def json_safe(value: object, depth: int = 0) -> JsonValue:
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


def message_copy(value: object) -> JsonObject | None:
    """The offending message as stored in a violation."""
    if value is None:
        return None
    safe = json_safe(value)
    return safe if isinstance(safe, dict) else {"value": safe}
