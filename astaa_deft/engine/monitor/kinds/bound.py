"""``bound``: one field of every message on a channel stays valid.

    - {name: finite_command, kind: bound, channel: command, field: acceleration,
       finite: true, min: -8, max: 4}
    - {name: nonempty_traj, kind: bound, channel: trajectory, field: points, non_empty: true}
    - {name: speeds, kind: bound, channel: trajectory, field: "points[*].v", min: 0}
    - {name: gear_known, kind: bound, channel: trajectory, field: gear, in_enum: true}

A field that is missing, or has the wrong shape, breaks the bound too: the
consumer could not use it either. With ``[*]`` every element is checked
(an empty array has nothing to break).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar
from collections.abc import Callable

from astaa_deft.model.fields import FieldPath, get
from astaa_deft.io.yamlsource import Node
from astaa_deft.engine.monitor.base import NO_VIOLATIONS, EpisodeGate, Invariant, Monitor, MonitorContext
from astaa_deft.engine.monitor.paths import Missing, compile_values
from astaa_deft.engine.monitor.spec_reader import InvariantReader
from astaa_deft.engine.monitor.violation import Violation
from astaa_deft.engine.monitor.kinds import Kind

KEYS = ("channel", "field", "min", "max", "finite", "non_empty", "in_enum")
REQUIRED = ("channel", "field")


@dataclass(frozen=True, kw_only=True)
class BoundInvariant(Invariant):
    kind: ClassVar[str] = "bound"

    channel: str
    field: FieldPath
    minimum: float | None = None
    maximum: float | None = None
    finite: bool = False
    non_empty: bool = False
    enum_values: tuple[object, ...] | None = None  # in_enum: the declared values

    def margin_source(self) -> tuple[str, FieldPath] | None:
        """The bounded field, when the bound has an end (min or max)."""
        return (self.channel, self.field) if self.minimum is not None or self.maximum is not None else None

    def margin_of(self, value: object) -> float | None:
        """The value's distance to the nearer end, normalised by the range when the bound has both ends (so
        invariants compare); 0 when it is not finite or out of bounds; None for a value that is no number."""
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            return None
        if not math.isfinite(value):
            return 0.0
        span = (self.maximum - self.minimum) if self.minimum is not None and self.maximum is not None else 1.0
        ends = [value - self.minimum if self.minimum is not None else math.inf,
                self.maximum - value if self.maximum is not None else math.inf]
        return max(0.0, min(ends)) / (span or 1.0)


def parse(reader: InvariantReader, node: Node, common: dict) -> BoundInvariant | None:
    v = node.value
    channel = reader.channel(v.get("channel"))
    if channel is None:
        return None
    found = reader.field(v.get("field"), channel.type, "'field'")
    if found is None:
        return None
    path, declared = found
    minimum = reader.number(v.get("min"), "'min'")
    maximum = reader.number(v.get("max"), "'max'")
    finite = bool(reader.boolean(v.get("finite"), "'finite'"))
    non_empty = bool(reader.boolean(v.get("non_empty"), "'non_empty'"))
    in_enum = bool(reader.boolean(v.get("in_enum"), "'in_enum'"))
    numeric = declared.kind not in ("string", "bytes", "bool", "enum", "struct", "array")
    field_node = v["field"]
    if (minimum is not None or maximum is not None or finite) and not numeric:
        reader.problem(field_node, f"'min', 'max' and 'finite' need a numeric field; '{path}' is "
                                   f"{declared.describe()}", "use non_empty or in_enum, or pick a numeric field")
        return None
    if non_empty and declared.kind not in ("array", "string", "bytes"):
        reader.problem(field_node, f"'non_empty' needs an array or a string; '{path}' is {declared.describe()}",
                       "use min/max for numbers")
        return None
    if in_enum and declared.kind != "enum":
        reader.problem(field_node, f"'in_enum' needs an enum field; '{path}' is {declared.describe()}",
                       "declare the field as {enum: [...]} or drop in_enum")
        return None
    if minimum is not None and maximum is not None and minimum > maximum:
        reader.problem(v["min"], f"'min' {minimum:g} is greater than 'max' {maximum:g}", "swap them")
        return None
    if not any(key in v for key in ("min", "max", "finite", "non_empty", "in_enum")):
        reader.problem(node, "a bound invariant checks nothing", "add min, max, finite, non_empty or in_enum")
        return None
    return BoundInvariant(channel=channel.name, field=path, minimum=minimum, maximum=maximum, finite=finite,
                          non_empty=non_empty, enum_values=declared.values if in_enum else None, **common)


def _value_check(inv: BoundInvariant) -> Callable[[Any], str | None]:
    """One closure answering 'what is wrong with this value?' (None: nothing)."""
    lo, hi, finite, values = inv.minimum, inv.maximum, inv.finite, inv.enum_values
    numeric = lo is not None or hi is not None or finite
    isfinite, isnan = math.isfinite, math.isnan

    def check(value: Any) -> str | None:
        if numeric:
            if type(value) is not float and type(value) is not int:
                return f"{value!r} is not a number"
            if isnan(value):
                return "NaN"
            if finite and not isfinite(value):
                return f"{value} is not finite"
            if lo is not None and value < lo:
                return f"{value:g} < min {lo:g}"
            if hi is not None and value > hi:
                return f"{value:g} > max {hi:g}"
        if values is not None and value not in values:
            return f"{value!r} is not one of {', '.join(map(repr, values))}"
        if inv.non_empty:
            if type(value) not in (list, str, bytes):
                return f"{type(value).__name__} where an array or string belongs"
            if not value:
                return "empty"
        return None

    return check


class BoundMonitor(Monitor):
    judges_undecodable: ClassVar[bool] = True  # an undecodable payload breaks it

    def __init__(self, invariant: BoundInvariant, context: MonitorContext):
        super().__init__(invariant, context)
        self.inv = invariant
        self._values = compile_values(invariant.field)
        self._check = _value_check(invariant)
        self._gate = EpisodeGate()

    def channels(self) -> set[str]:
        return {self.inv.channel}

    def on_message(self, channel: str, time_ns: int, value: dict | None, seq: int) -> list[Violation]:
        self.evaluations += 1
        problem = self._problem(value)
        if problem is None:
            self._gate.held()
            return NO_VIOLATIONS
        self.violating += 1
        if not self._gate.broke():
            return NO_VIOLATIONS
        return [self.violation(time_ns, problem, channel=channel, seq=seq, message=value)]

    def _problem(self, value: dict | None) -> str | None:
        if value is None:
            return "the payload could not be decoded"
        try:
            found = self._values(value)
        except Missing as missing:
            return f"'{missing.args[0]}' is missing"
        check = self._check
        for index, item in enumerate(found):
            problem = check(item)
            if problem is not None:
                return f"{self._place(value, index)}: {problem}"
        return None

    def _place(self, message: dict, index: int) -> str:
        """The concrete path of the index-th value read (slow path: only on a violation)."""
        path = self.inv.field
        if path.is_concrete:
            return str(path)
        matches = get(message, path)  # same document order as compile_values
        return str(matches[index][0]) if index < len(matches) else str(path)


def monitor(invariant: BoundInvariant, context: MonitorContext) -> BoundMonitor:
    return BoundMonitor(invariant, context)


Kind.register(BoundInvariant, KEYS, REQUIRED, parse=parse, monitor=monitor)
