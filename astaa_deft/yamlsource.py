"""YAML read into values that remember where they came from.

Every validator that reports a user's mistake needs the line and column of
the offending key or value; PyYAML's composed nodes carry them, so we walk
nodes instead of plain dicts.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import yaml

from .errors import InputError, Problem


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

    def items(self) -> Iterator[tuple[str, "Node"]]:
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
    def from_file(cls, path: Path) -> "Source":
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            raise InputError(Problem(str(path), None, None, "file not found", "check the path")) from None
        except IsADirectoryError:
            raise InputError(Problem(str(path), None, None, "is a directory", "give a YAML file")) from None
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(Problem(str(path), None, None, f"cannot read: {exc}", "")) from None
        return cls(text, str(path))

    def parse(self) -> Node:
        try:
            root = yaml.compose(self.text, Loader=yaml.SafeLoader)
        except yaml.MarkedYAMLError as exc:
            mark = exc.problem_mark
            line, col = (mark.line + 1, mark.column + 1) if mark else (None, None)
            raise InputError(
                Problem(self.name, line, col, f"not valid YAML: {exc.problem}", "fix the YAML syntax here")
            ) from None
        except yaml.YAMLError as exc:
            raise InputError(Problem(self.name, None, None, f"not valid YAML: {exc}", "")) from None
        if root is None:
            raise InputError(Problem(self.name, 1, 1, "the file is empty", "see docs for the expected layout"))
        return self._convert(root)

    def _convert(self, node: yaml.Node) -> Node:
        line, col = node.start_mark.line + 1, node.start_mark.column + 1
        if isinstance(node, yaml.MappingNode):
            out = Node({}, line, col)
            for key_node, value_node in node.value:
                key = _scalar(key_node)
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
        return Node(_scalar(node), line, col)

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


_constructor = yaml.SafeLoader("")


def _scalar(node: yaml.Node) -> Any:
    if not isinstance(node, yaml.ScalarNode):
        return f"<{node.tag}>"
    return _constructor.construct_object(node, deep=True)


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
