"""``arrays``: an array in another order (reversed, shuffled, two elements swapped), cut (to half, to one,
to none) or with an element twice (same id): each element plausible, the whole wrong."""

from __future__ import annotations

from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import ValueFamily

_KEYS = ("array.reversed", "array.element_duplicated", "array.cut_to_half", "array.two_swapped",
         "array.shuffled", "array.one_element", "array.empty")


class Arrays(ValueFamily):
    name = "arrays"
    weight = 5
    rank = 9
    owns = ("array.reversed", "array.shuffled", "array.cut_to_half", "array.element_duplicated",
            "array.two_swapped")
    keys_of_kind = {"array": _KEYS}


FAMILIES.register(Arrays.name, Arrays())
