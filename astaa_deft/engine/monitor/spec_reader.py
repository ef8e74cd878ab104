"""Reading an invariant's YAML: typed values, or a located problem and ``None``.

Every check reports through ``Source`` (file, line, column, fix) and keeps
going, so one ``spec check`` lists every mistake; callers skip an invariant
when a part of it came back ``None``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence

from astaa_deft.model.errors import did_you_mean
from astaa_deft.model.fields import FieldPath, FieldPathError, type_at
from astaa_deft.model.sut import Channel, FieldType, MessageType
from astaa_deft.io.yamlsource import Node, Source, describe_value
from astaa_deft.engine.monitor.expression import (
    CompiledExpression,
    ExpressionError,
    Ty,
    compile_expression,
    ty_of,
)

NAME_RE = re.compile(r"^[A-Za-z0-9_-]+\Z")


class InvariantReader:
    def __init__(self, src: Source, types: Mapping[str, MessageType], channels: Sequence[Channel],
                 modules: Sequence[str]):
        self.src = src
        self.types = types
        self.channels = {c.name: c for c in channels}
        self.modules = list(modules)

    # -- reporting -----------------------------------------------------------
    def problem(self, node: Node, message: str, fix: str = "") -> None:
        self.src.at(node, message, fix)

    def problem_inside(self, node: Node, offset: int, message: str, fix: str = "") -> None:
        """A problem at character ``offset`` of a scalar's text (a field path, an expression)."""
        self.src.report(node.line, self._column_of(node, offset), message, fix)

    def _column_of(self, node: Node, offset: int) -> int:
        # The node's column is where the scalar starts, quote included; point
        # past the quote. A scalar spanning lines keeps its start column.
        text = node.value if isinstance(node.value, str) else ""
        if "\n" in text:
            return node.column
        lines = self.src.text.splitlines()
        start = lines[node.line - 1][node.column - 1:node.column] if 0 < node.line <= len(lines) else ""
        return node.column + (1 if start in ("'", '"') else 0) + offset

    # -- structure -----------------------------------------------------------
    def keys(self, node: Node, allowed: Sequence[str], required: Sequence[str], what: str) -> bool:
        """Report unknown and missing keys; False if there were any (or ``node`` is no mapping).

        Callers stop there: a misspelt key would otherwise cascade into
        "lacks ..." and "checks nothing" reports about the same typo.
        """
        if not node.is_map:
            self.problem(node, f"{what} must be a mapping", f"write it as 'key: value' pairs ({', '.join(allowed)})")
            return False
        ok = True
        for key in node.value:
            if key not in allowed:
                hint = did_you_mean(key, allowed) or f"allowed keys: {', '.join(allowed)}"
                self.src.at_key(node, key, f"unknown key '{key}' in {what}", hint)
                ok = False
        for key in required:
            if key not in node.value:
                self.problem(node, f"{what} lacks '{key}'", f"add '{key}: …'")
                ok = False
        return ok

    # -- scalars -------------------------------------------------------------
    def text(self, node: Node | None, what: str, example: str) -> str | None:
        if node is None:
            return None
        if not isinstance(node.value, str) or not node.value.strip():
            self.problem(node, f"{what} must be a non-empty string", f"e.g. {example}")
            return None
        return node.value

    def name(self, node: Node, what: str) -> str | None:
        value = self.text(node, what, "speed_limit")
        if value is not None and not NAME_RE.match(value):
            self.problem(node, f"{what} '{value}' has characters other than letters, digits, '_' and '-'",
                         "rename it (it appears in logs and reports)")
            return None
        return value

    def number(self, node: Node | None, what: str, *, positive: bool = False,
               minimum: float | None = None, maximum: float | None = None) -> float | None:
        if node is None:
            return None
        value = node.value
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            self.problem(node, f"{what} must be a finite number, not {describe_value(value)}",
                         f"e.g. {what.strip(chr(39))}: 0.5")
            return None
        if positive and value <= 0:
            self.problem(node, f"{what} must be greater than 0, got {value:g}", "give a positive number")
            return None
        if minimum is not None and value < minimum:
            self.problem(node, f"{what} must be at least {minimum:g}, got {value:g}", f"use a value ≥ {minimum:g}")
            return None
        if maximum is not None and value > maximum:
            self.problem(node, f"{what} must be at most {maximum:g}, got {value:g}", f"use a value ≤ {maximum:g}")
            return None
        return float(value)

    def boolean(self, node: Node | None, what: str) -> bool | None:
        if node is None:
            return None
        if not isinstance(node.value, bool):
            self.problem(node, f"{what} must be true or false, not {describe_value(node.value)}", f"write {what}: true")
            return None
        return node.value

    def choice(self, node: Node | None, what: str, choices: Sequence[str]) -> str | None:
        if node is None:
            return None
        if not isinstance(node.value, str) or node.value not in choices:
            shown = node.value if isinstance(node.value, str) else describe_value(node.value)
            hint = (did_you_mean(shown, choices) if isinstance(node.value, str) else "") or \
                f"one of: {', '.join(choices)}"
            self.problem(node, f"{what} must be one of {', '.join(choices)}, not '{shown}'", hint)
            return None
        return node.value

    # -- references ----------------------------------------------------------
    def channel(self, node: Node | None) -> Channel | None:
        name = self.text(node, "'channel'", "trajectory")
        if name is None:
            return None
        if name not in self.channels:
            hint = did_you_mean(name, self.channels) or f"declared channels: {', '.join(self.channels)}"
            self.problem(node, f"unknown channel '{name}'", hint)  # type: ignore[arg-type]
            return None
        channel = self.channels[name]
        if channel.type not in self.types:
            return None  # the channel's own declaration is wrong; the loader reports that
        return channel

    def module_list(self, node: Node | None, example: str) -> tuple[str, ...] | None:
        """The modules a ``modules:`` key names (every module of the spec when absent); None after a problem."""
        if node is None:
            return tuple(self.modules)
        if not node.is_list or not node.value:
            self.problem(node, "'modules' must be a non-empty list of module names", f"e.g. modules: [{example}]")
            return None
        names = [self.module(item) for item in node.value]
        if any(n is None for n in names):
            return None
        return tuple(n for n in names if n is not None)

    def module(self, node: Node) -> str | None:
        name = self.text(node, "a module name", "control")
        if name is None:
            return None
        if name not in self.modules:
            hint = did_you_mean(name, self.modules) or f"declared modules: {', '.join(self.modules)}"
            self.problem(node, f"unknown module '{name}'", hint)
            return None
        return name

    def field(self, node: Node | None, type_name: str, what: str,
              kinds: Sequence[str] | None = None, *, relative_to: FieldType | None = None
              ) -> tuple[FieldPath, FieldType] | None:
        """A field path declared in ``type_name`` (or inside ``relative_to``, an array element's type).

        ``kinds`` restricts the static kind of the field (see ``expression.Ty``).
        """
        text = self.text(node, what, "header.stamp")
        if text is None or node is None:
            return None
        owner = relative_to.ref if relative_to is not None and relative_to.ref else type_name
        try:
            path = FieldPath.parse(text)
            declared = type_at(self.types, owner, path)
        except FieldPathError as exc:
            self.problem_inside(node, exc.position or 0, f"{what}: {exc.reason}",
                                f"name a field of {owner} (see 'types' in the spec)")
            return None
        if kinds is not None and ty_of(declared).kind not in kinds:
            self.problem(node, f"{what} '{text}' is {ty_of(declared).describe()}; "
                               f"this needs {' or '.join(_kind_words(kinds))}",
                         "pick a field of that type")
            return None
        return path, declared

    def expression(self, node: Node | None, type_name: str, what: str,
                   want: Sequence[str] = ("bool",)) -> CompiledExpression | None:
        text = self.text(node, what, '"speed <= 30"')
        if text is None or node is None:
            return None
        try:
            return compile_expression(text, self.types, type_name, want)
        except ExpressionError as exc:
            self.problem_inside(node, exc.position, f"{what}: {exc.message}", exc.fix)
            return None

    def number_or_field(self, node: Node | None, type_name: str, what: str,
                        relative_to: FieldType | None = None) -> float | FieldPath | None:
        """A fixed number (``width: 1.9``) or a numeric field path (``width: size.w``)."""
        if node is None:
            return None
        if isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            return self.number(node, what, positive=True)
        found = self.field(node, type_name, what, kinds=("number",), relative_to=relative_to)
        return found[0] if found else None


def _kind_words(kinds: Sequence[str]) -> list[str]:
    return [Ty(k).describe() if k in ("number", "bool", "string", "bytes") else f"an {k}" for k in kinds]
