"""The dictionary model: named entries grouped by declared field type, and the values they give.

An entry is a literal value or a derive rule (:mod:`.rules`); a test case
refers to one as ``dict:GROUP.NAME``. Whether a channel's codec can carry a
value is decided here too (``Dictionary.usable``), so generation never picks
such values and the engine skips them with the codec's reason instead of
failing mid-run.
"""

from __future__ import annotations

import base64
import copy
import enum
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Final, Literal

from astaa_deft.io.codecs import Codec
from astaa_deft.model.errors import AstaaDeftError, did_you_mean
from astaa_deft.model.sut import FLOAT_KINDS, INT_KINDS, FieldType
from astaa_deft.engine.intercept.dictionary.rules import RULES, FieldSite, FieldValue, NotApplicable, ValueContext

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
_REF = re.compile(r"dict:([A-Za-z_][A-Za-z0-9_]*)\.([A-Za-z_][A-Za-z0-9_]*)")


class UnknownEntry(AstaaDeftError, KeyError):
    """No dictionary entry by that reference; the message says what was meant, if anything."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0])


# ---------------------------------------------------------------- entries

class _Dynamic(enum.Enum):
    """``static_value()`` of an entry computed per mutation."""

    TOKEN = enum.auto()


DYNAMIC: Final = _Dynamic.TOKEN
Dynamic = Literal[_Dynamic.TOKEN]


@dataclass(frozen=True, kw_only=True)
class Entry:
    """One named value: a literal (``value``) or a derive rule (``rule``)."""

    group: str
    name: str
    value: FieldValue = None
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

    def static_value(self, site: FieldSite) -> FieldValue | Dynamic:
        """The value for ``site`` if it does not depend on the message, else ``DYNAMIC``.

        Call ``problem`` first: a static rule raises NotApplicable here otherwise.
        """
        if self.rule is None:
            return copy.deepcopy(self.value)
        rule = RULES[self.rule]
        return rule.compute(site, None) if rule.static else DYNAMIC

    def resolve(self, context: ValueContext) -> FieldValue:
        """The value for one concrete place; raises NotApplicable with the reason."""
        if self.rule is None:
            return copy.deepcopy(self.value)
        problem = RULES[self.rule].problem(context.site)
        if problem:
            raise NotApplicable(problem)
        return RULES[self.rule].compute(context.site, context)


def wire_value(value: FieldValue, field_type: FieldType, codec: Codec) -> FieldValue:
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

    def usable(self, site: FieldSite, codec: Codec, entries: Iterable[Entry] | None = None
               ) -> tuple[list[Entry], list[tuple[Entry, str]]]:
        """The field's entries (or ``entries``, from any group) split into usable ones and (entry, reason)
        skipped ones.

        Dynamic entries are usable here; their value is checked per mutation.
        """
        usable: list[Entry] = []
        skipped: list[tuple[Entry, str]] = []
        for entry in self.entries_for(site) if entries is None else entries:
            reason = entry.problem(site)
            value = entry.static_value(site) if reason is None else DYNAMIC
            if value is not DYNAMIC:  # a dynamic entry's value is checked per mutation
                reason = codec.carries(wire_value(value, site.field_type, codec))
            if reason is None:
                usable.append(entry)
            else:
                skipped.append((entry, reason))
        return usable, skipped
