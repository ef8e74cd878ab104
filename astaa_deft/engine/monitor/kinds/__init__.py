"""The invariant kinds, one module each, each registering itself on ``KINDS``.

A kind module provides ``KEYS`` (its own YAML keys), ``REQUIRED`` (those
that must be given), ``parse(reader, node, common)`` (YAML -> its frozen
Invariant dataclass, or None after reporting why) and ``monitor(invariant,
context)`` (a ``base.Monitor``), and registers them as a :class:`Kind` on
:data:`KINDS` (a ``model.registry.Registry``). Adding a kind is adding a
module here: the spec reader's list of kinds (``kind: …``, its "did you
mean", the keys it allows) and the monitor set are read from the registry.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from astaa_deft.engine.monitor.base import Invariant
from astaa_deft.model.registry import Registry


@dataclass(frozen=True, kw_only=True)
class Kind:
    """One invariant kind: its YAML keys, the reader of its entry and the maker of its monitor."""

    name: str
    keys: tuple[str, ...]
    required: tuple[str, ...]
    parse: Callable
    monitor: Callable
    invariant_type: type[Invariant]

    @classmethod
    def register(cls, invariant_type: type[Invariant], keys: tuple[str, ...], required: tuple[str, ...], *,
                 parse: Callable, monitor: Callable) -> Kind:
        """Register the kind whose invariants are ``invariant_type`` (its ``kind`` is the name)."""
        name = invariant_type.kind
        return KINDS.register(name,
            cls(name=name, keys=keys, required=required, parse=parse, monitor=monitor, invariant_type=invariant_type))


KINDS: Registry[Kind] = Registry("monitor kind", __name__)


def invariant_class(kind: str) -> type[Invariant]:
    """The invariant class of the kind named ``kind`` (a spec entry's ``kind``, a violation record's
    ``invariant_kind``): its traits say what can judge it. A name no kind registers gets the base
    :class:`Invariant`, every trait at its default."""
    entry = KINDS.get(kind)
    return entry.invariant_type if entry is not None else Invariant
