"""The checks every section of a spec shares: keys of a mapping, scalar kinds, names, numbers.

A ``SpecReader`` wraps the spec's ``Source``: each check reports a problem
(file, line, column, fix) on the source and returns a stand-in value, so one
load lists every mistake; ``Source.raise_if_problems`` raises them together.
Not thread-safe (a load's problems accumulate on its source).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from astaa_deft.io.yamlsource import Node, Source, describe_value
from astaa_deft.model.errors import did_you_mean

NAME_RE = re.compile(r"^[A-Za-z0-9_-]+\Z")
FIELD_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*\Z")
MAX_WAIT_S = 86_400.0  # a day: beyond it a wait is a typo, and timers overflow near 1e308


@dataclass(frozen=True)
class SpecReader:
    """The source being read, where relative paths start, and whether files it names must exist."""

    src: Source
    base_dir: Path
    from_file: bool = True  # False for a spec given as text: the paths it names are not checked

    def keys(self, node: Node, allowed: tuple[str, ...], required: tuple[str, ...], what: str) -> bool:
        """Report unknown and missing keys of a mapping; False if it is not a mapping."""
        if not node.is_map:
            self.src.at(node, f"{what} must be a mapping", f"write it as 'key: value' lines ({', '.join(allowed)})")
            return False
        for key in node.value:
            if key not in allowed:
                hint = did_you_mean(key, allowed) or f"allowed keys: {', '.join(allowed)}"
                self.src.at_key(node, key, f"unknown key '{key}' in {what}", hint)
        for key in required:
            if key not in node.value:
                self.src.at(node, f"{what} lacks '{key}'", f"add '{key}: …'")
        return True

    def expect(self, node: Node, kinds: tuple[type, ...], what: str, fix: str) -> bool:
        """True if the node's value is one of ``kinds`` (a bool only where ``bool`` is listed); else reported."""
        ok = isinstance(node.value, kinds) and not (bool not in kinds and isinstance(node.value, bool))
        if not ok:
            self.src.at(node, f"{what} must be {fix}, not {describe_value(node.value)}", f"write {what} as {fix}")
        return ok

    def name_of(self, node: Node, what: str) -> str:
        """A name that becomes part of Zenoh keys and file names ("?" after a problem)."""
        if not self.expect(node, (str,), what, "a string"):
            return "?"
        if not NAME_RE.match(node.value):
            self.src.at(node, f"{what} '{node.value}' has characters other than letters, digits, '_' and '-'",
                        "rename it (it becomes part of Zenoh keys and file names)")
        value: str = node.value
        return value

    def list_of_maps(self, node: Node | None, what: str, required: bool) -> list[Node]:
        """The entries of a list section (none when absent or not a list); an empty required one is reported."""
        if node is None:
            return []
        if not node.is_list:
            self.src.at(node, f"'{what}' must be a list", f"write each entry as '- name: …' under '{what}:'")
            return []
        if required and not node.value:
            self.src.at(node, f"'{what}' is empty", f"declare at least one entry under '{what}'")
        entries: list[Node] = node.value
        return entries

    def number(self, node: Node | None, what: str, minimum: float | None = None, strictly: bool = False,
               *, maximum: float | None = None) -> float | None:
        """A finite number within the bounds (``strictly``: above ``minimum``); None when absent or reported."""
        if node is None:
            return None
        if not self.expect(node, (int, float), what, "a number"):
            return None
        value = float(node.value)
        if value != value or value in (float("inf"), float("-inf")):
            self.src.at(node, f"{what} must be finite", "give a finite number")
            return None
        if minimum is not None and (value < minimum or (strictly and value == minimum)):
            self.src.at(node, f"{what} must be {'>' if strictly else '≥'} {minimum:g}", "give a larger value")
            return None
        if maximum is not None and value > maximum:
            self.src.at(node, f"{what} must be ≤ {maximum:g}", "give a smaller value")
            return None
        return value

    def module_ref(self, node: Node, name: str, module_names: list[str]) -> None:
        """Report ``name`` when it is not one of the declared modules."""
        if name not in module_names:
            hint = did_you_mean(name, module_names) or f"modules: {', '.join(module_names)}"
            self.src.at(node, f"unknown module '{name}'", hint)


def declared_channel(src: Source, node: Node, what: str, declared: Mapping[str, object]) -> str:
    """The channel ``node`` names (reported on ``src`` with a suggestion if it is not ``declared``; "" then)."""
    name = node.value if isinstance(node.value, str) else ""
    if name not in declared:
        shown = f"'{node.value}'" if isinstance(node.value, str) else f"({describe_value(node.value)})"
        src.at(node, f"{what} {shown} is not a declared channel",
               did_you_mean(name, declared) or "declare it under 'channels'")
    return name


def scalar_text(value: object) -> str:
    """A YAML scalar as the text a command line or an environment gets (booleans as YAML writes them)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)
