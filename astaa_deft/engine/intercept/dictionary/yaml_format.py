"""The dictionary file format: YAML groups of ``NAME: VALUE`` entries, validated with their places.

An entry is written as a plain value, ``{value: V}``, ``{repeat: V, times: N}``,
``{derive: RULE}`` or ``{remove: true}`` (see docs/policies.md). Every problem
of a file is reported together, at its line and column, with a fix.
"""

from __future__ import annotations

import enum
import re
from typing import Final, Literal

from astaa_deft.model.errors import did_you_mean
from astaa_deft.io.yamlsource import Node, Source, describe_value
from astaa_deft.engine.intercept.dictionary.model import GROUPS, KINDS_OF_GROUP, Entry
from astaa_deft.engine.intercept.dictionary.rules import RULES, FieldValue, is_field_value

# Groups whose plain numbers are meant as floats: `one: 1` in the float group is 1.0.
_FLOAT_GROUPS = ("float", "time")

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_MAX_REPEAT = 16 * 1024 * 1024  # a dictionary value is sent in a message: keep it sane


class _Reported(enum.Enum):
    """A problem was reported for this entry; it is left out."""

    TOKEN = enum.auto()


_REPORTED: Final = _Reported.TOKEN
Reported = Literal[_Reported.TOKEN]


class DictionaryFile:
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

    def entry(self, group: str, name: str, node: Node) -> Entry | None | Reported:
        """The entry, None for {remove: true}, or _REPORTED after reporting a problem."""
        origin = f"{self.src.name}:{node.line}"
        if not node.is_map:
            value = self.plain(node)
            if value is not _REPORTED and group in _FLOAT_GROUPS:
                value = self.as_float(node, value)
            elif value is not _REPORTED and group == "int" and type(value) is not int:
                self.src.at(node, f"the int group takes whole numbers, not {describe_value(value)}",
                            "write an integer (e.g. -1), or {value: ...} to send another value on purpose")
                value = _REPORTED
            return value if value is _REPORTED else Entry(group=group, name=name, value=value, origin=origin)
        keys = set(node.value)
        if keys == {"value"}:
            value = self.plain(node.value["value"])
            return value if value is _REPORTED else Entry(group=group, name=name, value=value, origin=origin)
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

    def repeat(self, group: str, name: str, node: Node, origin: str) -> Entry | Reported:
        unit, times = node.value["repeat"], node.value["times"]
        if type(unit.value) not in (str, bytes):
            self.src.at(unit, "'repeat' takes a string or a !!binary byte string", 'e.g. {repeat: "A", times: 8192}')
            return _REPORTED
        if type(times.value) is not int or not 0 <= times.value * max(len(unit.value), 1) <= _MAX_REPEAT:
            self.src.at(times, f"'times' must be an integer giving at most {_MAX_REPEAT} characters or bytes",
                        "e.g. times: 8192")
            return _REPORTED
        return Entry(group=group, name=name, value=unit.value * times.value, origin=origin)

    def derive(self, group: str, name: str, node: Node, origin: str) -> Entry | Reported:
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
        return Entry(group=group, name=name, rule=rule.name, origin=origin)

    def plain(self, node: Node) -> FieldValue | Reported:
        """The node's value if it is plain data a codec can hold, else _REPORTED."""
        value = node.plain()
        if is_field_value(value):
            return value
        self.src.at(node, _not_plain(value) or "not plain data",
                    "quote it to make it a string, or use !!binary for bytes")
        return _REPORTED

    def as_float(self, node: Node, value: FieldValue) -> FieldValue | Reported:
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


def _not_plain(value: object) -> str | None:
    if type(value) in (str, int, float, bool, bytes) or value is None:
        return None
    if type(value) is list:
        return next(filter(None, map(_not_plain, value)), None)
    if type(value) is dict:
        if any(type(k) is not str for k in value):
            return "object keys must be strings"
        return next(filter(None, map(_not_plain, value.values())), None)
    return f"YAML read this as {type(value).__name__}, which no message encoding carries"
