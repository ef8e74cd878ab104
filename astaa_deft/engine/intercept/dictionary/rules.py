"""Derive rules: exceptional values computed from the field being mutated.

A rule looks at a field's declaration (its bounds or width: ``static``,
computed once per field) or at the message being mutated (its current value,
the previous message on the channel, a sibling array: computed at mutation
time, from a :class:`ValueContext`). A rule that has no value for a field
raises :class:`NotApplicable` with the reason.
"""

from __future__ import annotations

import copy
import math
import random
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TypeGuard

from astaa_deft.model.errors import AstaaDeftError
from astaa_deft.model.json import FieldValue
from astaa_deft.model.fields import FieldPath, PathLike, as_path, type_at
from astaa_deft.model.sut import FLOAT_KINDS, INT_KINDS, INT_RANGES, FieldType, MessageType



def is_field_value(value: object) -> TypeGuard[FieldValue]:
    """Plain data a field can hold: None, a bool, number, str or bytes, or lists and string-keyed dicts of them."""
    if value is None or type(value) in (bool, int, float, str, bytes):
        return True
    if type(value) is list:
        return all(map(is_field_value, value))
    if type(value) is dict:
        return all(type(key) is str and is_field_value(item) for key, item in value.items())
    return False


class NotApplicable(AstaaDeftError):
    """A derive rule has no value for this field or message; the message is the reason."""



# ---------------------------------------------------------------- where a value goes

@dataclass(frozen=True)
class FieldSite:
    """A declared field: its type, and the struct type holding it (for sibling rules)."""

    field_type: FieldType
    parent: MessageType | None = None


def field_site(types: Mapping[str, MessageType], type_name: str, path: PathLike) -> FieldSite:
    """The site of ``path`` in a ``type_name`` message (raises FieldPathError if it does not exist)."""
    path = as_path(path)
    field_type = type_at(types, type_name, path)
    *parent_segments, last = path.segments
    if type(last) is not str:  # an array element: its "parent" is an array, no struct siblings
        return FieldSite(field_type)
    if not parent_segments:
        return FieldSite(field_type, types[type_name])
    parent_type = type_at(types, type_name, FieldPath(tuple(parent_segments)))
    if parent_type.kind != "struct" or parent_type.ref is None:
        return FieldSite(field_type)
    return FieldSite(field_type, types[parent_type.ref])


@dataclass(kw_only=True)
class ValueContext:
    """What a derive rule may look at when mutating one concrete place of a message."""

    site: FieldSite
    current: FieldValue  # the value at that place now
    container: FieldValue  # the dict (or list) holding it, for sibling arrays
    key: str | int  # where it sits in the container
    previous: Callable[[], FieldValue]  # the same place in the previous real message; raises NotApplicable


# ---------------------------------------------------------------- derive rules

@dataclass(frozen=True)
class Rule:
    """A derive rule. ``kinds``: declared kinds it applies to (None: any leaf).

    ``static`` rules depend on the declaration only and are computed once per
    field; the others run per mutation on a ``ValueContext``.
    """

    name: str
    kinds: frozenset[str] | None
    compute: Callable[[FieldSite, ValueContext | None], FieldValue]
    static: bool = False

    def problem(self, site: FieldSite) -> str | None:
        kind = site.field_type.kind
        if self.kinds is not None and kind not in self.kinds:
            wanted = ", ".join(sorted(self.kinds))
            return f"rule '{self.name}' applies to {wanted} fields, not {site.field_type.describe()}"
        if self.static:
            try:
                self.compute(site, None)
            except NotApplicable as exc:
                return str(exc)
        return None


def _bound(site: FieldSite, which: str) -> float:
    ftype = site.field_type
    value = ftype.minimum if which == "min" else ftype.maximum
    if value is None:
        raise NotApplicable(f"the field declares no {which}")
    return value


def _below_min(site: FieldSite, _ctx: ValueContext | None) -> FieldValue:
    low = _bound(site, "min")
    if site.field_type.kind in INT_KINDS:
        return math.ceil(low) - 1
    return math.nextafter(float(low), -math.inf)  # the closest value a range check must reject


def _above_max(site: FieldSite, _ctx: ValueContext | None) -> FieldValue:
    high = _bound(site, "max")
    if site.field_type.kind in INT_KINDS:
        return math.floor(high) + 1
    return math.nextafter(float(high), math.inf)


def _width(offset: int, end: int) -> Callable[[FieldSite, ValueContext | None], int]:
    return lambda site, _ctx: INT_RANGES[site.field_type.kind][end] + offset


def _negated(_site: FieldSite, ctx: ValueContext | None) -> bool:
    assert ctx is not None
    if type(ctx.current) is not bool:
        raise NotApplicable(f"the current value {ctx.current!r} is not a boolean")
    return not ctx.current


def _undefined_enum(site: FieldSite, _ctx: ValueContext | None) -> FieldValue:
    values = site.field_type.values
    numbers = [v for v in values if type(v) is int]
    if values and len(numbers) == len(values):
        return max(numbers) + 1
    candidate = "UNDEFINED"
    while candidate in values:
        candidate += "_"
    return candidate


def _case_swapped(site: FieldSite, _ctx: ValueContext | None) -> str:
    values = site.field_type.values
    for value in values:
        if isinstance(value, str) and value.swapcase() != value and value.swapcase() not in values:
            return value.swapcase()
    raise NotApplicable("no enum value has letters whose case can be swapped")


def _previous(_site: FieldSite, ctx: ValueContext | None) -> FieldValue:
    assert ctx is not None
    return copy.deepcopy(ctx.previous())


def _previous_minus_1s(_site: FieldSite, ctx: ValueContext | None) -> float:
    assert ctx is not None
    previous = ctx.previous()
    if not _is_number(previous):
        raise NotApplicable(f"the previous value {previous!r} is not a number of seconds")
    return float(previous) - 1.0


def _nonempty_list(ctx: ValueContext | None) -> list:
    assert ctx is not None
    if type(ctx.current) is not list:
        raise NotApplicable("the current value is not an array")
    if not ctx.current:
        raise NotApplicable("the array is empty: no element to repeat")
    return ctx.current


def _first_only(_site: FieldSite, ctx: ValueContext | None) -> list:
    return [copy.deepcopy(_nonempty_list(ctx)[0])]


def _ten_times_longer(_site: FieldSite, ctx: ValueContext | None) -> list:
    items = _nonempty_list(ctx)
    # Separate copies: a later policy setting points[3].v must not change points[0].v too.
    return [copy.deepcopy(item) for _ in range(10) for item in items]


def _sibling_length_mismatch(site: FieldSite, ctx: ValueContext | None) -> list:
    items = _nonempty_list(ctx)
    assert ctx is not None
    siblings = _sibling_arrays(site, ctx)
    if not siblings:
        raise NotApplicable("no sibling array in the same struct")
    target = len(siblings[0]) + 1  # consumers that zip parallel arrays must notice
    return [copy.deepcopy(items[i % len(items)]) for i in range(target)]


def _sibling_arrays(site: FieldSite, ctx: ValueContext) -> list[list]:
    if site.parent is None or type(ctx.container) is not dict:
        return []
    return [ctx.container[name] for name, ftype in site.parent.fields.items()
            if ftype.kind == "array" and name != ctx.key and type(ctx.container.get(name)) is list]


# ---------------------------------------------------------------- semantic rules: plausible but wrong
#
# Well-typed values a real upstream module produces by mistake: a declared bound hit exactly,
# a sign flipped, an angle off by a turn, a unit mixed up, an array in another order. The semantic fault
# families of ``astaa_deft.engine.intercept.faults`` draw them; they are ordinary dictionary entries too.

def _at_bound(which: str) -> Callable[[FieldSite, ValueContext | None], FieldValue]:
    def at(site: FieldSite, _ctx: ValueContext | None) -> FieldValue:
        value = _bound(site, which)
        if site.field_type.kind in INT_KINDS:
            return math.ceil(value) if which == "min" else math.floor(value)
        return float(value)
    return at


def _is_number(value: object) -> TypeGuard[int | float]:
    """An int or a float exactly: not a bool, nor a subclass of either."""
    return type(value) in (int, float)


def _number(ctx: ValueContext | None) -> float | int:
    assert ctx is not None
    value = ctx.current
    if not _is_number(value):
        raise NotApplicable(f"the current value {value!r} is not a number")
    if type(value) is float and not math.isfinite(value):
        raise NotApplicable(f"the current value {value!r} is not finite")
    return value


def _sign_flipped(_site: FieldSite, ctx: ValueContext | None) -> FieldValue:
    value = _number(ctx)
    if value == 0:
        raise NotApplicable("the current value is zero: its sign flipped is itself")
    return -value


def _offset(delta: float) -> Callable[[FieldSite, ValueContext | None], float]:
    return lambda _site, ctx: float(_number(ctx)) + delta


def _scaled(factor: float) -> Callable[[FieldSite, ValueContext | None], FieldValue]:
    def scale(site: FieldSite, ctx: ValueContext | None) -> FieldValue:
        value = _number(ctx)
        if value == 0:
            raise NotApplicable("the current value is zero: scaling it changes nothing")
        if site.field_type.kind in INT_KINDS:
            return round(value * factor)
        return float(value) * factor
    return scale


def _list_of(ctx: ValueContext | None, at_least: int) -> list:
    assert ctx is not None
    if type(ctx.current) is not list:
        raise NotApplicable("the current value is not an array")
    if len(ctx.current) < at_least:
        raise NotApplicable(f"the array has {len(ctx.current)} element(s): fewer than {at_least}")
    return ctx.current


def _reversed(_site: FieldSite, ctx: ValueContext | None) -> list:
    return copy.deepcopy(_list_of(ctx, 2)[::-1])


def _shuffled(_site: FieldSite, ctx: ValueContext | None) -> list:
    """A fixed shuffle (seeded by the length, so a rerun sends the same order), never the identity."""
    items = _list_of(ctx, 2)
    order = list(range(len(items)))
    random.Random(len(items)).shuffle(order)
    if order == sorted(order):
        order = order[1:] + order[:1]
    return [copy.deepcopy(items[i]) for i in order]


def _cut_to_half(_site: FieldSite, ctx: ValueContext | None) -> list:
    items = _list_of(ctx, 3)
    return copy.deepcopy(items[:len(items) // 2])


def _element_duplicated(_site: FieldSite, ctx: ValueContext | None) -> list:
    """The middle element twice in a row (same id, same values)."""
    items = _list_of(ctx, 1)
    middle = len(items) // 2
    return copy.deepcopy(items[:middle + 1] + items[middle:])


def _two_swapped(_site: FieldSite, ctx: ValueContext | None) -> list:
    """The first two elements exchanged."""
    items = copy.deepcopy(_list_of(ctx, 2))
    items[0], items[1] = items[1], items[0]
    return items


_NUMBERS = frozenset(FLOAT_KINDS + INT_KINDS + ("time",))
_FLOATS = frozenset(FLOAT_KINDS)
_ARRAYS = frozenset({"array"})
RULES: dict[str, Rule] = {rule.name: rule for rule in (
    Rule("below_min", _NUMBERS, _below_min, static=True),
    Rule("above_max", _NUMBERS, _above_max, static=True),
    Rule("width_min", frozenset(INT_KINDS), _width(0, 0), static=True),
    Rule("width_max", frozenset(INT_KINDS), _width(0, 1), static=True),
    Rule("width_underflow", frozenset(INT_KINDS), _width(-1, 0), static=True),
    Rule("width_overflow", frozenset(INT_KINDS), _width(1, 1), static=True),
    Rule("negated", frozenset({"bool"}), _negated),
    Rule("undefined_value", frozenset({"enum"}), _undefined_enum, static=True),
    Rule("case_swapped", frozenset({"enum"}), _case_swapped, static=True),
    Rule("previous", None, _previous),
    Rule("previous_minus_1s", frozenset(FLOAT_KINDS + ("time",)), _previous_minus_1s),
    Rule("first_only", frozenset({"array"}), _first_only),
    Rule("ten_times_longer", frozenset({"array"}), _ten_times_longer),
    Rule("sibling_length_mismatch", frozenset({"array"}), _sibling_length_mismatch),
    # semantic: plausible but wrong
    Rule("at_min", _NUMBERS, _at_bound("min"), static=True),
    Rule("at_max", _NUMBERS, _at_bound("max"), static=True),
    Rule("sign_flipped", _NUMBERS, _sign_flipped),
    Rule("plus_2pi", _FLOATS, _offset(2 * math.pi)),
    Rule("minus_2pi", _FLOATS, _offset(-2 * math.pi)),
    Rule("plus_pi", _FLOATS, _offset(math.pi)),
    Rule("minus_pi", _FLOATS, _offset(-math.pi)),
    Rule("unwrapped", _FLOATS, _offset(4 * math.pi)),
    Rule("times_1000", _NUMBERS, _scaled(1000.0)),
    Rule("div_1000", _FLOATS, _scaled(0.001)),
    Rule("deg_to_rad", _FLOATS, _scaled(math.pi / 180.0)),
    Rule("rad_to_deg", _FLOATS, _scaled(180.0 / math.pi)),
    Rule("reversed", _ARRAYS, _reversed),
    Rule("shuffled", _ARRAYS, _shuffled),
    Rule("cut_to_half", _ARRAYS, _cut_to_half),
    Rule("element_duplicated", _ARRAYS, _element_duplicated),
    Rule("two_swapped", _ARRAYS, _two_swapped),
)}
