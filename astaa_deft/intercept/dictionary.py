"""The dictionary of exceptional values: load, merge, and pick values for a field.

A dictionary is a set of named entries grouped by declared field type
(``float``, ``int``, ``bool``, ``string``, ``bytes``, ``time``, ``enum``,
``array``); a test case refers to one as ``dict:GROUP.NAME``. The default
file ships in ``astaa_deft/data/dictionaries/default.yaml``; users add or
override entries with their own files, merged in order (see docs/policies.md).

An entry is either a literal value or a *derive rule*: a value computed from
the field being mutated (its declared bounds or width, its current value,
the previous message on the channel, a sibling array). Rules that only need
the declaration are computed once per field; the others at mutation time.

Whether a channel's codec can carry a value is decided here too
(``Dictionary.usable``), so generation never picks such values and the
engine skips them with the codec's reason instead of failing mid-run.
"""

from __future__ import annotations

import base64
import copy
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

from ..codecs import Codec
from ..errors import AstaaDeftError, did_you_mean
from ..fields import FieldPath, PathLike, as_path, type_at
from ..spec.model import FLOAT_KINDS, INT_KINDS, INT_RANGES, FieldType, MessageType
from ..yamlsource import Node, Source

DEFAULT_DICTIONARY = Path(__file__).resolve().parent.parent / "data" / "dictionaries" / "default.yaml"
REF_PREFIX = "dict:"

# Which group holds the exceptional values of each declared kind.
GROUP_OF_KIND: dict[str, str] = {
    **{kind: "float" for kind in FLOAT_KINDS},
    **{kind: "int" for kind in INT_KINDS},
    "bool": "bool", "string": "string", "bytes": "bytes", "time": "time",
    "enum": "enum", "array": "array",
}
GROUPS = ("float", "int", "bool", "string", "bytes", "time", "enum", "array")
KINDS_OF_GROUP: dict[str, frozenset[str]] = {
    group: frozenset(kind for kind, g in GROUP_OF_KIND.items() if g == group) for group in GROUPS
}
# Groups whose plain numbers are meant as floats: `one: 1` in the float group is 1.0.
_FLOAT_GROUPS = ("float", "time")

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_REF = re.compile(r"dict:([A-Za-z_][A-Za-z0-9_]*)\.([A-Za-z_][A-Za-z0-9_]*)")
_MAX_REPEAT = 16 * 1024 * 1024  # a dictionary value is sent in a message: keep it sane


class NotApplicable(AstaaDeftError):
    """A derive rule has no value for this field or message; the message is the reason."""


class UnknownEntry(AstaaDeftError, KeyError):
    """No dictionary entry by that reference; the message says what was meant, if anything."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


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


@dataclass
class ValueContext:
    """What a derive rule may look at when mutating one concrete place of a message."""

    site: FieldSite
    current: Any  # the value at that place now
    container: Any  # the dict (or list) holding it, for sibling arrays
    key: str | int  # where it sits in the container
    previous: Callable[[], Any]  # the same place in the previous real message; raises NotApplicable


# ---------------------------------------------------------------- derive rules

@dataclass(frozen=True)
class Rule:
    """A derive rule. ``kinds``: declared kinds it applies to (None: any leaf).

    ``static`` rules depend on the declaration only and are computed once per
    field; the others run per mutation on a ``ValueContext``.
    """

    name: str
    kinds: frozenset[str] | None
    compute: Callable[[FieldSite, ValueContext | None], Any]
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


def _below_min(site: FieldSite, _ctx: ValueContext | None) -> Any:
    low = _bound(site, "min")
    if site.field_type.kind in INT_KINDS:
        return math.ceil(low) - 1
    return math.nextafter(float(low), -math.inf)  # the closest value a range check must reject


def _above_max(site: FieldSite, _ctx: ValueContext | None) -> Any:
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


def _undefined_enum(site: FieldSite, _ctx: ValueContext | None) -> Any:
    values = site.field_type.values
    if values and all(type(v) is int for v in values):
        return max(values) + 1
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


def _previous(_site: FieldSite, ctx: ValueContext | None) -> Any:
    assert ctx is not None
    return copy.deepcopy(ctx.previous())


def _previous_minus_1s(_site: FieldSite, ctx: ValueContext | None) -> float:
    assert ctx is not None
    previous = ctx.previous()
    if type(previous) not in (int, float):
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


_NUMBERS = frozenset(FLOAT_KINDS + INT_KINDS + ("time",))
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
)}


# ---------------------------------------------------------------- entries

_DYNAMIC = object()  # static_value() of an entry computed per mutation


@dataclass(frozen=True)
class Entry:
    """One named value: a literal (``value``) or a derive rule (``rule``)."""

    group: str
    name: str
    value: Any = None
    rule: str | None = None
    origin: str = ""  # file:line where it was defined, for messages

    @property
    def key(self) -> str:
        return f"{self.group}.{self.name}"

    @property
    def ref(self) -> str:
        return f"{REF_PREFIX}{self.key}"

    @property
    def is_dynamic(self) -> bool:
        return self.rule is not None and not RULES[self.rule].static

    def problem(self, site: FieldSite) -> str | None:
        """Why this entry has no value for that field at all (None: it may have one)."""
        return RULES[self.rule].problem(site) if self.rule else None

    def static_value(self, site: FieldSite) -> Any:
        """The value for ``site`` if it does not depend on the message, else ``DYNAMIC``.

        Call ``problem`` first: a static rule raises NotApplicable here otherwise.
        """
        if self.rule is None:
            return copy.deepcopy(self.value)
        rule = RULES[self.rule]
        return rule.compute(site, None) if rule.static else _DYNAMIC

    def resolve(self, context: ValueContext) -> Any:
        """The value for one concrete place; raises NotApplicable with the reason."""
        if self.rule is None:
            return copy.deepcopy(self.value)
        problem = RULES[self.rule].problem(context.site)
        if problem:
            raise NotApplicable(problem)
        return RULES[self.rule].compute(context.site, context)


DYNAMIC = _DYNAMIC


def wire_value(value: Any, field_type: FieldType, codec: Codec) -> Any:
    """``value`` as it travels in a field of that type: JSON writes ``bytes`` fields as base64 text."""
    if field_type.kind == "bytes" and codec.name == "json" and type(value) is bytes:
        return base64.b64encode(value).decode("ascii")
    return value


# ---------------------------------------------------------------- the dictionary

class Dictionary:
    """Entries by key (``group.name``), after merging all files in order."""

    def __init__(self, entries: Iterable[Entry], sources: Sequence[str] = ()):
        self.entries: dict[str, Entry] = {entry.key: entry for entry in entries}
        self.sources = tuple(sources)

    def __contains__(self, key: str) -> bool:
        return key in self.entries

    def __len__(self) -> int:
        return len(self.entries)

    def get(self, key: str) -> Entry:
        return self.entries[key]

    def lookup(self, ref: str) -> Entry:
        """The entry a ``dict:GROUP.NAME`` reference names (UnknownEntry with a readable reason)."""
        match = _REF.fullmatch(ref)
        if not match:
            raise UnknownEntry(f"{ref!r} is not a dictionary reference; write dict:GROUP.NAME, e.g. dict:float.nan")
        key = f"{match.group(1)}.{match.group(2)}"
        if key not in self.entries:
            hint = self.suggest(key)
            raise UnknownEntry(f"unknown dictionary entry {ref!r}" + (f"; {hint}" if hint else ""))
        return self.entries[key]

    def suggest(self, ref: str) -> str:
        """A "did you mean 'dict:...'?" for an unknown reference or key, or ''."""
        key = ref[len(REF_PREFIX):] if ref.startswith(REF_PREFIX) else ref
        hint = did_you_mean(key, self.entries)
        return hint.replace("'", "'" + REF_PREFIX, 1) if hint else ""

    def group(self, name: str) -> list[Entry]:
        return [entry for entry in self.entries.values() if entry.group == name]

    def entries_for(self, site: FieldSite) -> list[Entry]:
        """The entries of the group of the field's declared type, in file order."""
        group = GROUP_OF_KIND.get(site.field_type.kind)
        return self.group(group) if group else []

    def usable(self, site: FieldSite, codec: Codec) -> tuple[list[Entry], list[tuple[Entry, str]]]:
        """The field's entries split into usable ones and (entry, reason) skipped ones.

        Dynamic entries are usable here; their value is checked per mutation.
        """
        usable: list[Entry] = []
        skipped: list[tuple[Entry, str]] = []
        for entry in self.entries_for(site):
            reason = entry.problem(site)
            if reason is None and not entry.is_dynamic:
                reason = codec.carries(wire_value(entry.static_value(site), site.field_type, codec))
            if reason is None:
                usable.append(entry)
            else:
                skipped.append((entry, reason))
        return usable, skipped


# ---------------------------------------------------------------- loading

def load_dictionary(files: Sequence[Path | str] = (), *, include_default: bool = True) -> Dictionary:
    """The default dictionary (unless excluded) merged with ``files`` in order.

    A later entry with the same ``group.name`` replaces the earlier one;
    ``{remove: true}`` deletes it. All problems of a file are reported together.
    """
    paths = ([DEFAULT_DICTIONARY] if include_default else []) + [Path(f) for f in files]
    merged: dict[str, Entry] = {}
    for path in paths:
        _merge(merged, _DictionaryFile(Source.from_file(path)).read())
    return Dictionary(merged.values(), [str(p) for p in paths])


def dictionary_from_text(text: str, name: str = "<dictionary>", *, include_default: bool = True) -> Dictionary:
    """Like ``load_dictionary`` with one more file given as text (tests, tools)."""
    base = load_dictionary() if include_default else Dictionary(())
    merged = dict(base.entries)
    _merge(merged, _DictionaryFile(Source(text, name)).read())
    return Dictionary(merged.values(), base.sources + (name,))


def _merge(merged: dict[str, Entry], read: list[tuple[str, Entry | None]]) -> None:
    for key, entry in read:
        if entry is None:
            merged.pop(key, None)
        else:
            merged[key] = entry


class _DictionaryFile:
    """Validates one dictionary file; yields (key, Entry or None for a removal)."""

    def __init__(self, source: Source):
        self.src = source

    def read(self) -> list[tuple[str, Entry | None]]:
        root = self.src.parse()
        found: list[tuple[str, Entry | None]] = []
        if not root.is_map:
            self.src.at(root, "a dictionary is a mapping of groups", "start with e.g. 'float:'")
            self.src.raise_if_problems()
        for group, entries in root.items():
            if group not in GROUPS:
                hint = did_you_mean(group, GROUPS)
                self.src.at_key(root, group, f"unknown group '{group}'" + (f"; {hint}" if hint else ""),
                                "groups are " + ", ".join(GROUPS))
                continue
            if not entries.is_map:
                self.src.at(entries, f"group '{group}' must be a mapping of NAME: VALUE",
                            "e.g. 'nan: .nan' on its own indented line")
                continue
            for name, node in entries.items():
                if not _NAME.fullmatch(name):
                    self.src.at_key(entries, name, f"entry name '{name}' is not a plain identifier",
                                    "use letters, digits and _ (it is written dict:GROUP.NAME)")
                    continue
                entry = self.entry(group, name, node)
                if entry is not _REPORTED:
                    found.append((f"{group}.{name}", entry))
        self.src.raise_if_problems()
        return found

    def entry(self, group: str, name: str, node: Node) -> Any:
        """The entry, None for {remove: true}, or _REPORTED after reporting a problem."""
        origin = f"{self.src.name}:{node.line}"
        if not node.is_map:
            value = self.plain(node)
            if value is not _REPORTED and group in _FLOAT_GROUPS:
                value = self.as_float(node, value)
            return value if value is _REPORTED else Entry(group, name, value=value, origin=origin)
        keys = set(node.value)
        if keys == {"value"}:
            value = self.plain(node.value["value"])
            return value if value is _REPORTED else Entry(group, name, value=value, origin=origin)
        if keys == {"repeat", "times"}:
            return self.repeat(group, name, node, origin)
        if keys == {"derive"}:
            return self.derive(group, name, node.value["derive"], origin)
        if keys == {"remove"}:
            if node.value["remove"].value is not True:
                self.src.at(node.value["remove"], "'remove' takes true", "write {remove: true}")
                return _REPORTED
            return None
        self.src.at(node, f"entry '{group}.{name}': unknown form with keys {sorted(keys)}",
                    "write a plain value, {value: V}, {repeat: V, times: N}, {derive: RULE} or {remove: true}")
        return _REPORTED

    def repeat(self, group: str, name: str, node: Node, origin: str) -> Any:
        unit, times = node.value["repeat"], node.value["times"]
        if type(unit.value) not in (str, bytes):
            self.src.at(unit, "'repeat' takes a string or a !!binary byte string", 'e.g. {repeat: "A", times: 8192}')
            return _REPORTED
        if type(times.value) is not int or not 0 <= times.value * max(len(unit.value), 1) <= _MAX_REPEAT:
            self.src.at(times, f"'times' must be an integer giving at most {_MAX_REPEAT} characters or bytes",
                        "e.g. times: 8192")
            return _REPORTED
        return Entry(group, name, value=unit.value * times.value, origin=origin)

    def derive(self, group: str, name: str, node: Node, origin: str) -> Any:
        rule = RULES.get(node.value) if isinstance(node.value, str) else None
        if rule is None:
            hint = did_you_mean(str(node.value), RULES)
            self.src.at(node, f"unknown derive rule {node.value!r}" + (f"; {hint}" if hint else ""),
                        "rules: " + ", ".join(RULES))
            return _REPORTED
        if rule.kinds is not None and not rule.kinds & KINDS_OF_GROUP[group]:
            self.src.at(node, f"rule '{rule.name}' does not apply to the {group} group",
                        f"it applies to {', '.join(sorted(rule.kinds))} fields")
            return _REPORTED
        return Entry(group, name, rule=rule.name, origin=origin)

    def plain(self, node: Node) -> Any:
        """The node's value if it is plain data a codec can hold, else _REPORTED."""
        value = node.plain()
        problem = _not_plain(value)
        if problem:
            self.src.at(node, problem, "quote it to make it a string, or use !!binary for bytes")
            return _REPORTED
        return value

    def as_float(self, node: Node, value: Any) -> Any:
        """Plain numbers and numeric strings in the float/time groups are floats."""
        if type(value) is int:
            try:
                return float(value)
            except OverflowError:
                self.src.at(node, f"{value} is too large for a float", "write .inf, or put it in the int group")
                return _REPORTED
        if type(value) is str:
            try:
                return float(value)
            except ValueError:
                self.src.at(node, f"{value!r} is not a number",
                            "write a number (e.g. 1.0e+16, .nan, -.inf), or {value: ...} to send a string on purpose")
                return _REPORTED
        return value


_REPORTED = object()  # a problem was reported for this entry; it is left out


def _not_plain(value: Any) -> str | None:
    if type(value) in (str, int, float, bool, bytes) or value is None:
        return None
    if type(value) is list:
        return next(filter(None, map(_not_plain, value)), None)
    if type(value) is dict:
        if any(type(k) is not str for k in value):
            return "object keys must be strings"
        return next(filter(None, map(_not_plain, value.values())), None)
    return f"YAML read this as {type(value).__name__}, which no message encoding carries"
