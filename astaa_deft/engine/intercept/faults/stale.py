"""``stale``: a field carrying the previous message's value (a producer that sends a cached copy), on one
message or held (each held message one behind)."""

from __future__ import annotations

from astaa_deft.model.sut import FLOAT_KINDS, INT_KINDS
from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import ValueFamily

_OWN = ("float.previous", "int.previous", "string.previous", "enum.previous", "array.previous")


class Stale(ValueFamily):
    name = "stale"
    weight = 4
    rank = 10
    owns = _OWN
    keys_of_kind = {**{kind: ("float.previous",) for kind in FLOAT_KINDS},
                    **{kind: ("int.previous",) for kind in INT_KINDS},
                    "string": ("string.previous",), "enum": ("enum.previous",), "array": ("array.previous",)}


FAMILIES.register(Stale.name, Stale())
