"""``units``: a value sent in the wrong unit (× 1000: m as mm; ÷ 1000: mm as m; degrees as radians and
back) — well-typed, finite, and off by a constant factor no range check on one message may notice."""

from __future__ import annotations

from astaa_deft.model.sut import FLOAT_KINDS, INT_KINDS
from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import ValueFamily

_FLOAT = ("float.times_1000", "float.rad_to_deg", "float.div_1000", "float.deg_to_rad")


class Units(ValueFamily):
    name = "units"
    weight = 5
    rank = 8
    owns = _FLOAT + ("int.times_1000",)
    keys_of_kind = {**{kind: _FLOAT for kind in FLOAT_KINDS}, **{kind: ("int.times_1000",) for kind in INT_KINDS}}


FAMILIES.register(Units.name, Units())
