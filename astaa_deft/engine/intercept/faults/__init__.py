"""Fault families: one module each, registered in ``FAMILIES`` (see ``base`` for the interface).

To add a family, add a module here with a :class:`FaultFamily` subclass
whose instance it registers (``FAMILIES.register(name, instance)``): the
generator draws it by its ``weight``, a campaign probes it if it is
``semantic``, and ``astaa-deft generate --family NAME`` draws it alone. Nothing else
changes.
"""

from __future__ import annotations

from astaa_deft.model.registry import Registry
from astaa_deft.engine.intercept.faults.base import FaultFamily, Scene, Sources, Target, Targets

FAMILIES: Registry[FaultFamily] = Registry("fault family", __name__)


def by_rank() -> list[FaultFamily]:
    """Every family in draw order (its ``rank``)."""
    return sorted(FAMILIES.values(), key=lambda family: family.rank)


def weights() -> dict[str, int]:
    """Each family's weight, in draw order: the one table of the mix."""
    return {family.name: family.weight for family in by_rank()}


def owned_entries() -> frozenset[str]:
    """Dictionary keys that only their family draws (the exceptional-value families leave them out)."""
    return frozenset(key for family in FAMILIES.values() for key in family.owns)


__all__ = ["FAMILIES", "FaultFamily", "Scene", "Sources", "Target", "Targets", "by_rank", "owned_entries",
           "weights"]
