"""YAML read into values that remember where they came from.

Every validator that reports a user's mistake needs the line and column of
the offending key or value; PyYAML's composed nodes carry them, so we walk
nodes instead of plain dicts.
"""

from __future__ import annotations

import copy
import datetime
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeAlias
from collections.abc import Iterable, Iterator

import yaml

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.inputfile import InputKind, read_input

# What a YAML scalar reads as once positions are dropped (PyYAML's safe constructors:
# !!binary gives bytes, a timestamp a date or datetime), and a value made of them.
YamlScalar: TypeAlias = str | int | float | bool | None | bytes | datetime.date
YamlValue: TypeAlias = YamlScalar | list["YamlValue"] | dict[str, "YamlValue"]


@dataclass
class Node:
    """A YAML node: ``value`` is a dict[str, Node], a list[Node] or a scalar."""

    # Any, not the union it is (dict[str, Node] | list[Node] | YamlScalar): every reader checks the kind
    # it expects with ``is_map``/``is_list`` (or reports the node) and then uses the value as that kind;
    # properties do not narrow a union for the type checker, so the union would cost a cast or an
    # isinstance at each of those places (mypy reports some 1600 uses across the spec, monitor and
    # dictionary readers) without checking anything more than they already do.
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

    def plain(self) -> YamlValue:
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
        """The file read through :func:`~astaa_deft.io.inputfile.read_input`; raises ``InputError``."""
        return cls(decode_utf8(read_input(path, kind), str(path)), str(path))

    def parse(self) -> Node:
        """The document as a tree of :class:`Node`; ``InputError`` (file:line:column) for invalid or hostile YAML."""
        try:
            try:
                root = self._build(yaml.parse(self.text, Loader=_FAST_LOADER))
            except yaml.YAMLError:  # PyYAML's own parser is the reference: its verdict and its message
                self.problems.clear()
                root = self._build(yaml.parse(self.text, Loader=yaml.SafeLoader))
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark
            line, col = (mark.line + 1, mark.column + 1) if mark else (None, None)
            raise InputError(
                Problem(self.name, line, col, f"not valid YAML: {exc.problem}", "fix the YAML syntax here")
            ) from None
        except yaml.reader.ReaderError as exc:  # placed by an offset, not by a mark
            line, col = line_column(self.text, exc.position)
            code = ord(exc.character) if isinstance(exc.character, str) else exc.character
            raise InputError(Problem(self.name, line, col, f"not valid YAML: the control character #x{code:04x}",
                                     "remove it, or write it as an escape in a double-quoted string")) from None
        except yaml.YAMLError as exc:
            raise InputError(Problem(self.name, None, None, f"not valid YAML: {exc}", "")) from None
        if root is None:
            raise InputError(Problem(self.name, 1, 1, "the file is empty", "see docs for the expected layout"))
        return root

    def _build(self, events: Iterable[yaml.Event]) -> Node | None:
        """The tree from the parser's events in one pass, refusing what would exhaust the stack or memory.

        Without recursion (an explicit stack of open collections), so deep
        nesting is measured and refused rather than overflowing; an alias
        expands into a copy of its anchor's subtree, counted against
        MAX_NODES before it is copied (a few hundred bytes of nested aliases
        would expand to billions of nodes). PyYAML's composer is not used: it
        is quadratic in the length of a long sequence.
        """
        stack: list[_Open] = []
        anchors: dict[str, tuple[Node, int]] = {}  # a finished anchored node and its size in nodes
        root: Node | None = None
        documents = aliases = 0
        self._budget = MAX_NODES
        self._first_alias: tuple[int, int] | None = None
        for event in events:
            tag = getattr(event, "tag", None)
            if tag is not None and tag != "!" and not tag.startswith("tag:yaml.org,2002:"):
                raise self._refuse(event, f"custom tag '{tag}' is not supported", "remove the tag")
            if isinstance(event, yaml.DocumentStartEvent):
                documents += 1
                if documents > 1:
                    raise self._refuse(event, "a second YAML document ('---') in the file", "keep one document")
            elif isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                if len(stack) >= MAX_DEPTH:
                    raise self._refuse(event, f"nested more than {MAX_DEPTH} levels deep", "flatten the structure")
                if stack and stack[-1].wants_key:
                    kind = "a mapping" if isinstance(event, yaml.MappingStartEvent) else "a list"
                    raise self._refuse(event, f"a key must be a plain word, not {kind}", "write the key as text")
                value: dict | list = {} if isinstance(event, yaml.MappingStartEvent) else []
                stack.append(_Open(node=Node(value, *_place(event)), anchor=event.anchor))
            elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                done = stack.pop()
                if done.anchor is not None:
                    anchors[done.anchor] = (done.node, done.size)
                root = self._attach(stack, done.node, done.size) or root
            elif isinstance(event, yaml.ScalarEvent):
                if event.tag is None and event.value == "<<" and not event.style:
                    raise self._refuse(event, "merge keys ('<<') are not supported", "write the keys out")
                start: Any = event.start_mark  # libyaml's Mark or PyYAML's: the same fields
                end: Any = event.end_mark
                node = yaml.ScalarNode(_scalar_tag(event), event.value, start, end, event.style or None)
                if stack and stack[-1].wants_key:
                    self._key(stack[-1], self._scalar(node), *_place(event))
                    continue
                built = Node(self._scalar(node), *_place(event))
                if event.anchor is not None:
                    anchors[event.anchor] = (built, 1)
                root = self._attach(stack, built, 1) or root
            elif isinstance(event, yaml.AliasEvent):
                aliases += 1
                if self._first_alias is None:
                    self._first_alias = _place(event)
                if aliases > MAX_ALIASES:
                    raise self._refuse(event, f"more than {MAX_ALIASES} aliases (*{event.anchor})",
                                       "write the values out instead of repeating anchors")
                if event.anchor not in anchors:
                    raise self._refuse(event, f"alias *{event.anchor} names no anchor defined (and closed) before it",
                                       f"define &{event.anchor} first; an anchor cannot contain itself")
                anchored, size = anchors[event.anchor]
                if stack and stack[-1].wants_key:
                    if anchored.is_map or anchored.is_list:
                        raise self._refuse(event, "a key must be a plain word, not an alias of a collection",
                                           "write the key as text")
                    self._key(stack[-1], anchored.value, *_place(event))
                    continue
                self._spend(size)  # before the copy: a bomb is refused, never built
                root = self._attach(stack, copy.deepcopy(anchored), size, counted=True) or root
        return root

    def _key(self, parent: _Open, key: object, line: int, column: int) -> None:
        if not isinstance(key, str):
            self.report(line, column, f"key {key!r} is not a string", "quote it")
            key = str(key)
        if key in parent.node.value:
            self.report(line, column, f"duplicate key '{key}'", "remove one of them")
        parent.key, parent.key_mark = key, (line, column)

    def _attach(self, stack: list[_Open], node: Node, size: int, counted: bool = False) -> Node | None:
        """Put a finished node into the open collection; the node itself when it is the document's root."""
        if not counted:
            self._spend(1 if node.is_map or node.is_list else size)
        if not stack:
            return node
        parent = stack[-1]
        parent.size += size
        if parent.node.is_list:
            parent.node.value.append(node)
        else:
            assert parent.key is not None
            parent.node.value[parent.key] = node
            parent.node.key_marks[parent.key] = parent.key_mark
            parent.key = None
        return None

    def _spend(self, nodes: int) -> None:
        self._budget -= nodes
        if self._budget < 0 and self._first_alias is not None:
            raise InputError(Problem(self.name, *self._first_alias,
                                     f"the document expands to more than {MAX_NODES:,} values (through aliases)",
                                     "write the values out instead of nesting aliases"))
        if self._budget < 0:
            raise InputError(Problem(self.name, None, None, f"the document holds more than {MAX_NODES:,} values",
                                     "no spec, dictionary or scenario needs that many; check the file"))

    def _refuse(self, event: yaml.Event, message: str, fix: str) -> InputError:
        return InputError(Problem(self.name, *_place(event), message, fix))

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

    def _scalar(self, node: yaml.ScalarNode) -> YamlScalar:
        line, col = node.start_mark.line + 1, node.start_mark.column + 1
        if len(node.value) > MAX_SCALAR_DIGITS and node.tag in _NUMBER_TAGS:
            raise InputError(Problem(self.name, line, col, f"a number of {len(node.value):,} characters",
                                     "use a number of at most 100 digits"))
        if node.style is None and node.tag == "tag:yaml.org,2002:str" and len(node.value) <= MAX_SCALAR_DIGITS \
                and _EXPONENT_NUMBER.match(node.value):
            return float(node.value)  # YAML 1.2 reads 1e3 as a number; PyYAML's 1.1 rules would make it text
        if node.tag == "tag:yaml.org,2002:str":
            return node.value  # what the constructor would return, without its per-node bookkeeping
        try:
            return _constructor.construct_object(node, deep=True)
        except (yaml.YAMLError, ValueError, OverflowError) as exc:
            problem = getattr(exc, "problem", None) or str(exc)
            raise InputError(Problem(self.name, line, col, f"cannot read the value {node.value[:40]!r}: {problem}",
                                     "write a plain number or text")) from None
        finally:
            _constructor.constructed_objects.clear()  # it would keep every node it ever constructed


@dataclass(kw_only=True)
class _Open:
    """A mapping or list being built: its node, anchor, size in nodes so far and the key awaiting its value."""

    node: Node
    anchor: str | None
    size: int = 1
    key: str | None = None
    key_mark: tuple[int, int] = (0, 0)

    @property
    def wants_key(self) -> bool:
        return self.node.is_map and self.key is None


def _place(event: yaml.Event) -> tuple[int, int]:
    """The event's 1-based line and column (the parser marks every event)."""
    mark = event.start_mark
    assert mark is not None
    return mark.line + 1, mark.column + 1


def _scalar_tag(event: yaml.ScalarEvent) -> str:
    """The scalar's tag as PyYAML's composer resolves it (plain 12 is an int, quoted '12' a string)."""
    if event.tag is None or event.tag == "!":
        return _constructor.resolve(yaml.ScalarNode, event.value, event.implicit)
    return event.tag


MAX_DEPTH = 64  # no spec, dictionary or scenario needs more; Python's stack does not allow 500
MAX_ALIASES = 100
MAX_NODES = 200_000  # after alias expansion
MAX_SCALAR_DIGITS = 100

_constructor = yaml.SafeLoader("")
# libyaml's event parser when PyYAML was built with it (~15x faster). It refuses a little more than
# PyYAML's (a lone surrogate escape, "\udc80"), so a document it refuses is read again by PyYAML's.
_FAST_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


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


def describe_value(value: object) -> str:
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
