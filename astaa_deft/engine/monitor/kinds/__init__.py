"""The invariant kinds, one module each, behind one interface.

Each kind module provides ``KEYS`` (its own YAML keys), ``REQUIRED`` (those
that must be given), ``parse(reader, node, common)`` (YAML -> its frozen
Invariant dataclass, or None after reporting why) and ``monitor(invariant,
context)`` (a ``base.Monitor``). Adding a kind is adding a module and a
line below.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType
from collections.abc import Callable

from astaa_deft.engine.monitor.kinds import bound, collision, deadline, exceptions, expression, log, process, temporal


@dataclass(frozen=True)
class Kind:
    name: str
    keys: tuple[str, ...]
    required: tuple[str, ...]
    parse: Callable
    monitor: Callable
    invariant_type: type


def _kind(module: ModuleType, invariant_type: type) -> Kind:
    name = invariant_type.kind  # type: ignore[attr-defined]
    return Kind(name, module.KEYS, module.REQUIRED, module.parse, module.monitor, invariant_type)


KINDS: dict[str, Kind] = {
    kind.name: kind
    for kind in (
        _kind(process, process.ProcessInvariant),
        _kind(deadline, deadline.DeadlineInvariant),
        _kind(bound, bound.BoundInvariant),
        _kind(expression, expression.ExpressionInvariant),
        _kind(temporal, temporal.TemporalInvariant),
        _kind(collision, collision.CollisionInvariant),
        _kind(log, log.LogInvariant),
        _kind(exceptions, exceptions.ExceptionsInvariant),
    )
}
