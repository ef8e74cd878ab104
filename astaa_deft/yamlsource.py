"""YAML read into values that remember where they came from.

Every validator that reports a user's mistake needs the line and column of
the offending key or value; PyYAML's composed nodes carry them, so we walk
nodes instead of plain dicts.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from collections.abc import Iterator

import yaml

from .errors import InputError, Problem
from .inputfile import InputKind, read_input


@dataclass
class Node:
    """A YAML node: ``value`` is a dict[str, Node], a list[Node] or a scalar."""

    value: Any
    line: int  # 1-based
    column: int  # 1-based
    key_marks: dict[str, tuple[int, int]] = field(default_factory=dict)

    @property
    def is_map(self) -> bool:
        return isinstance(self.value, dict)

    @property
    def is_list(self) -> bool:
        return isinstance(self.value, list)

    def items(self) -> Iterator[tuple[str, Node]]:
        return iter(self.value.items())

    def plain(self) -> Any:
        """The value with all positions dropped."""
        if self.is_map:
            return {k: v.plain() for k, v in self.value.items()}
        if self.is_list:
            return [v.plain() for v in self.value]
        return self.value


class Source:
    """One YAML file (or string) and a way to report problems inside it."""

    def __init__(self, text: str, name: str):
        self.text = text
        self.name = name
        self.problems: list[Problem] = []

    @classmethod
    def from_file(cls, path: Path, kind: InputKind) -> Source:
        """The file read through :func:`~astaa_deft.inputfile.read_input`; raises ``InputError``."""
        return cls(decode_utf8(read_input(path, kind), str(path)), str(path))

    def parse(self) -> Node:
        try:
            self._prescan()
            root = yaml.compose(self.text, Loader=yaml.SafeLoader)
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark
            line, col = (mark.line + 1, mark.column + 1) if mark else (None, None)
            raise InputError(
                Problem(self.name, line, col, f"not valid YAML: {exc.problem}", "fix the YAML syntax here")
            ) from None
        except yaml.reader.ReaderError as exc:  # placed by character offset, not by a mark
            line, col = line_column(self.text, exc.position)
            code = ord(exc.character) if isinstance(exc.character, str) else exc.character
            raise InputError(Problem(self.name, line, col, f"not valid YAML: the control character #x{code:04x}",
                                     "remove it, or write it as an escape in a double-quoted string")) from None
        except yaml.YAMLError as exc:
            raise InputError(Problem(self.name, None, None, f"not valid YAML: {exc}", "")) from None
        if root is None:
            raise InputError(Problem(self.name, 1, 1, "the file is empty", "see docs for the expected layout"))
        self._budget = MAX_NODES
        return self._convert(root)

    def _prescan(self) -> None:
        """Refuse, before anything is built, what would exhaust the stack or memory.

        The event parser is iterative, so deep nesting and alias counts are
        measured here without recursion; the composer and our own walk are
        recursive and an alias expands into a copy of its anchor's subtree
        (a few hundred bytes of nested aliases would expand to billions of nodes).
        """
        depth = 0
        aliases = 0
        self._first_alias: tuple[int, int] | None = None
        for event in yaml.parse(self.text, Loader=yaml.SafeLoader):
            if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                depth += 1
                if depth > MAX_DEPTH:
                    raise self._refuse(event, f"nested more than {MAX_DEPTH} levels deep",
                                       "flatten the structure")
            elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                depth -= 1
            elif isinstance(event, yaml.AliasEvent):
                aliases += 1
                mark = event.start_mark
                if self._first_alias is None and mark is not None:
                    self._first_alias = (mark.line + 1, mark.column + 1)
                if aliases > MAX_ALIASES:
                    raise self._refuse(event, f"more than {MAX_ALIASES} aliases (*{event.anchor})",
                                       "write the values out instead of repeating anchors")
            tag = getattr(event, "tag", None)
            if tag is not None and tag != "!" and not tag.startswith("tag:yaml.org,2002:"):
                raise self._refuse(event, f"custom tag '{tag}' is not supported", "remove the tag")
            if isinstance(event, yaml.ScalarEvent) and event.tag is None and event.value == "<<" \
                    and event.style is None:
                raise self._refuse(event, "merge keys ('<<') are not supported", "write the keys out")

    def _refuse(self, event, message: str, fix: str) -> InputError:
        mark = event.start_mark
        return InputError(Problem(self.name, mark.line + 1, mark.column + 1, message, fix))

    def _convert(self, node: yaml.Node) -> Node:
        line, col = node.start_mark.line + 1, node.start_mark.column + 1
        self._budget -= 1
        if self._budget < 0:
            line, col = self._first_alias or (line, col)
            raise InputError(Problem(self.name, line, col,
                                     f"the document expands to more than {MAX_NODES:,} values (through aliases)",
                                     "write the values out instead of nesting aliases"))
        if isinstance(node, yaml.MappingNode):
            out = Node({}, line, col)
            for key_node, value_node in node.value:
                key = self._scalar(key_node)
                kline, kcol = key_node.start_mark.line + 1, key_node.start_mark.column + 1
                if not isinstance(key, str):
                    self.report(kline, kcol, f"key {key!r} is not a string", "quote it")
                    key = str(key)
                if key in out.value:
                    self.report(kline, kcol, f"duplicate key '{key}'", "remove one of them")
                out.value[key] = self._convert(value_node)
                out.key_marks[key] = (kline, kcol)
            return out
        if isinstance(node, yaml.SequenceNode):
            return Node([self._convert(item) for item in node.value], line, col)
        return Node(self._scalar(node), line, col)

    def report(self, line: int | None, column: int | None, message: str, fix: str = "") -> None:
        self.problems.append(Problem(self.name, line, column, message, fix))

    def at(self, node: Node, message: str, fix: str = "") -> None:
        self.report(node.line, node.column, message, fix)

    def at_key(self, parent: Node, key: str, message: str, fix: str = "") -> None:
        line, col = parent.key_marks.get(key, (parent.line, parent.column))
        self.report(line, col, message, fix)

    def raise_if_problems(self) -> None:
        if self.problems:
            raise InputError(sorted(self.problems, key=lambda p: (p.line or 0, p.column or 0)))


    def _scalar(self, node: yaml.Node) -> Any:
        line, col = node.start_mark.line + 1, node.start_mark.column + 1
        if not isinstance(node, yaml.ScalarNode):
            kind = "a mapping" if isinstance(node, yaml.MappingNode) else "a list"
            raise InputError(Problem(self.name, line, col, f"a key must be a plain word, not {kind}",
                                     "write the key as text"))
        if len(node.value) > MAX_SCALAR_DIGITS and node.tag in _NUMBER_TAGS:
            raise InputError(Problem(self.name, line, col, f"a number of {len(node.value):,} characters",
                                     "use a number of at most 100 digits"))
        if node.style is None and node.tag == "tag:yaml.org,2002:str" and len(node.value) <= MAX_SCALAR_DIGITS \
                and _EXPONENT_NUMBER.match(node.value):
            return float(node.value)  # YAML 1.2 reads 1e3 as a number; PyYAML's 1.1 rules would make it text
        try:
            return _constructor.construct_object(node, deep=True)
        except (yaml.YAMLError, ValueError, OverflowError) as exc:
            problem = getattr(exc, "problem", None) or str(exc)
            raise InputError(Problem(self.name, line, col, f"cannot read the value {node.value[:40]!r}: {problem}",
                                     "write a plain number or text")) from None


MAX_DEPTH = 64  # no spec, dictionary or scenario needs more; Python's stack does not allow 500
MAX_ALIASES = 100
MAX_NODES = 200_000  # after alias expansion
MAX_SCALAR_DIGITS = 100

_constructor = yaml.SafeLoader("")


_EXPONENT_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+\Z")
_NUMBER_TAGS = ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float")


def line_column(text: str, offset: int) -> tuple[int, int]:
    """The 1-based line and column of a character offset into ``text``."""
    offset = max(0, min(offset, len(text)))
    line_start = text.rfind("\n", 0, offset) + 1
    return text.count("\n", 0, offset) + 1, offset - line_start + 1


def decode_utf8(data: bytes, name: str) -> str:
    """Text from bytes; a byte that is not UTF-8 is reported by line and column, not by offset."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        column = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise InputError(Problem(name, line, column, f"not UTF-8 text (byte 0x{data[exc.start]:02x})",
                                 "save the file as UTF-8")) from None


def describe_value(value: Any) -> str:
    """How an error message names a YAML value of the wrong kind."""
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    if value is None:
        return "empty"
    if isinstance(value, bool):
        return f"the boolean {str(value).lower()}"
    return f"{type(value).__name__} {value!r}"
