"""``expression``: a condition over the fields of each message on one channel.

    - {name: speed_limit, kind: expression, channel: status, expr: "ego_speed <= speed_limit + 0.5"}
    - {name: light_known, kind: expression, channel: lights,
       expr: "len(lights) == 0 or lights[0].state in ('red', 'yellow', 'green')"}

The language is in ``monitor/expression.py``. A message the expression
cannot be evaluated on (a field missing or of the wrong type, an index past
the end) breaks the invariant: the condition does not hold on it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from astaa_deft.io.yamlsource import Node
from astaa_deft.engine.monitor.base import NO_VIOLATIONS, EpisodeGate, Invariant, Monitor, MonitorContext
from astaa_deft.engine.monitor.expression import RUNTIME_ERRORS, CompiledExpression, describe_runtime_error
from astaa_deft.engine.monitor.spec_reader import InvariantReader
from astaa_deft.engine.monitor.violation import Violation
from astaa_deft.engine.monitor.kinds import Kind

KEYS = ("channel", "expr")
REQUIRED = ("channel", "expr")


@dataclass(frozen=True, kw_only=True)
class ExpressionInvariant(Invariant):
    kind: ClassVar[str] = "expression"

    channel: str
    expr: CompiledExpression


def parse(reader: InvariantReader, node: Node, common: dict) -> ExpressionInvariant | None:
    channel = reader.channel(node.value.get("channel"))
    if channel is None:
        return None
    compiled = reader.expression(node.value.get("expr"), channel.type, "'expr'")
    if compiled is None:
        return None
    return ExpressionInvariant(channel=channel.name, expr=compiled, **common)


class ExpressionMonitor(Monitor):
    judges_undecodable: ClassVar[bool] = True  # an undecodable payload breaks it

    def __init__(self, invariant: ExpressionInvariant, context: MonitorContext):
        super().__init__(invariant, context)
        self.inv = invariant
        self._evaluate = invariant.expr.evaluate
        self._gate = EpisodeGate()

    def channels(self) -> set[str]:
        return {self.inv.channel}

    def on_message(self, channel: str, time_ns: int, value: dict | None, seq: int) -> list[Violation]:
        self.evaluations += 1
        if value is None:
            problem = "the payload could not be decoded"
        else:
            try:
                if self._evaluate(value) is True:
                    self._gate.held()
                    return NO_VIOLATIONS
                problem = f"{self.inv.expr.text.strip()} is false"
            except RUNTIME_ERRORS as exc:
                problem = f"cannot evaluate {self.inv.expr.text.strip()}: {describe_runtime_error(exc)}"
        self.violating += 1
        if not self._gate.broke():
            return NO_VIOLATIONS
        return [self.violation(time_ns, problem, channel=channel, seq=seq, message=value)]


def monitor(invariant: ExpressionInvariant, context: MonitorContext) -> ExpressionMonitor:
    return ExpressionMonitor(invariant, context)


Kind.register(ExpressionInvariant, KEYS, REQUIRED, parse=parse, monitor=monitor)
