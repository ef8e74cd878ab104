"""The dictionary of exceptional values: load, merge, and pick values for a field.

A dictionary is a set of named entries grouped by declared field type
(``float``, ``int``, ``bool``, ``string``, ``bytes``, ``time``, ``enum``,
``array``); a test case refers to one as ``dict:GROUP.NAME``. The default
file ships in ``astaa_deft/data/dictionaries/default.yaml``; users add or
override entries with their own files, merged in order (see docs/policies.md).

* ``model``: entries, the ``Dictionary``, which values a codec can carry;
* ``rules``: derive rules — values computed from the field being mutated
  (its declared bounds or width, its current value, the previous message on
  the channel, a sibling array); rules that only need the declaration are
  computed once per field, the others at mutation time;
* ``yaml_format``: the file format, validated with line and column;
* ``loader``: ``load_dictionary`` / ``dictionary_from_text``, files merged in order.
"""

from __future__ import annotations

from astaa_deft.engine.intercept.dictionary.loader import DEFAULT_DICTIONARY, dictionary_from_text, load_dictionary
from astaa_deft.engine.intercept.dictionary.model import (
    DYNAMIC,
    GROUP_OF_KIND,
    GROUPS,
    KINDS_OF_GROUP,
    REF_PREFIX,
    Dictionary,
    Dynamic,
    Entry,
    UnknownEntry,
    wire_value,
)
from astaa_deft.engine.intercept.dictionary.rules import (
    RULES, FieldSite, FieldValue, NotApplicable, Rule, ValueContext, field_site, is_field_value,
)

__all__ = [
    "DEFAULT_DICTIONARY", "DYNAMIC", "GROUPS", "GROUP_OF_KIND", "KINDS_OF_GROUP", "REF_PREFIX", "RULES",
    "Dictionary", "Dynamic", "Entry", "FieldSite", "FieldValue", "NotApplicable", "Rule", "UnknownEntry",
    "ValueContext", "dictionary_from_text", "field_site", "is_field_value", "load_dictionary", "wire_value",
]
