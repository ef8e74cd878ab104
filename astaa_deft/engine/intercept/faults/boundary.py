"""``boundary``: a field's declared range hit exactly or just missed (min, max, min − ε, max + ε), zero,
negative zero, or its sign flipped: plausible values an off-by-one or a missing ``abs`` mishandles."""

from __future__ import annotations

from astaa_deft.model.sut import FLOAT_KINDS, INT_KINDS
from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import ValueFamily

_FLOAT = ("float.at_max", "float.at_min", "float.sign_flipped", "float.above_max", "float.below_min",
          "float.zero", "float.neg_zero")
_INT = ("int.at_max", "int.at_min", "int.sign_flipped", "int.above_max", "int.below_min", "int.zero")


class Boundary(ValueFamily):
    name = "boundary"
    weight = 6
    rank = 6
    owns = ("float.at_min", "float.at_max", "float.sign_flipped", "int.at_min", "int.at_max", "int.sign_flipped")
    keys_of_kind = {**{kind: _FLOAT for kind in FLOAT_KINDS}, **{kind: _INT for kind in INT_KINDS}}


FAMILIES.register(Boundary.name, Boundary())
