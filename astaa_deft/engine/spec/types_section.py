"""The spec's ``types:`` section (message types and their fields) and ``brittle:`` (fields not to mutate).

A field is a type name (``float64``, ``Point``, ``Point[]``) or a mapping
(``{type: float64, min: 0}``, ``{enum: [a, b]}``, ``{array: Point, max_length: 8}``).
Problems are reported on the reader's source; a bad field reads as a string.
"""

from __future__ import annotations

import re

from astaa_deft.engine.spec.reader import FIELD_NAME_RE, SpecReader
from astaa_deft.io.yamlsource import Node
from astaa_deft.model.errors import did_you_mean
from astaa_deft.model.fields import FieldPathError, check_brittle_pattern
from astaa_deft.model.sut import SCALAR_KINDS, FieldType, MessageType

TYPE_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*\Z")


def read_types_section(reader: SpecReader, node: Node | None) -> dict[str, MessageType]:
    """Each declared message type by name (a bad one stays known, without fields, so references to it
    are not reported too)."""
    if node is None:
        return {}
    if not node.is_map:
        reader.src.at(node, "'types' must be a mapping of type names to fields", "see docs/spec.md")
        return {}
    names = list(node.value)
    out: dict[str, MessageType] = {}
    for tname, tnode in node.items():
        if not TYPE_NAME_RE.match(tname):
            reader.src.at_key(node, tname, f"type name '{tname}' is not an identifier", "use letters, digits and '_'")
        if tname in SCALAR_KINDS or tname in ("enum", "array", "struct"):
            reader.src.at_key(node, tname, f"type name '{tname}' is a built-in kind", "rename it")
        if not tnode.is_map or not tnode.value:
            reader.src.at(tnode, f"type '{tname}' must map field names to field types", "e.g. 'x: float64'")
            out[tname] = MessageType(tname, {})  # keep the name known: later references are not errors too
            continue
        fields = {}
        for fname, fnode in tnode.items():
            if not FIELD_NAME_RE.match(fname):
                reader.src.at_key(tnode, fname, f"field name '{fname}' is not an identifier",
                                "use letters, digits and '_' (field paths use '.' and '[]')")
            fields[fname] = _field_type(reader, fnode, names, f"{tname}.{fname}")
        out[tname] = MessageType(tname, fields)
    _check_recursion(reader, out, node)
    return out


def _field_type(reader: SpecReader, node: Node, type_names: list[str], where: str) -> FieldType:
    if isinstance(node.value, str):
        return _type_expr(reader, node.value, node, type_names, where=where)
    if not node.is_map:
        reader.src.at(node, f"field '{where}' has no type", "write a type name, 'T[]', {enum: […]} or {array: T}")
        return FieldType(kind="string")
    v = node.value
    forms = [k for k in ("type", "enum", "array") if k in v]
    allowed = ("type", "enum", "array", "min", "max", "min_length", "max_length")
    reader.keys(node, allowed, (), f"field '{where}'")
    if len(forms) != 1:
        reader.src.at(node, f"field '{where}' needs exactly one of 'type', 'enum', 'array'",
                    "e.g. {type: float64, min: 0} or {enum: [a, b]} or {array: Point}")
        return FieldType(kind="string")
    minimum = reader.number(v.get("min"), f"'{where}.min'")
    maximum = reader.number(v.get("max"), f"'{where}.max'")
    min_len = _length(reader, v.get("min_length"), where)
    max_len = _length(reader, v.get("max_length"), where)
    if minimum is not None and maximum is not None and minimum > maximum:
        reader.src.at(v["min"], f"'{where}': min {minimum:g} > max {maximum:g}", "swap them")
    if min_len is not None and max_len is not None and min_len > max_len:
        reader.src.at(v["min_length"], f"'{where}': min_length > max_length", "swap them")
    form = forms[0]
    if form == "enum":
        enode = v["enum"]
        if not enode.is_list or not enode.value:
            reader.src.at(enode, f"enum of '{where}' must be a non-empty list", "e.g. {enum: [red, yellow, green]}")
            return FieldType(kind="string")
        values = tuple(e.plain() for e in enode.value)
        if len(set(map(repr, values))) != len(values):
            reader.src.at(enode, f"enum of '{where}' repeats a value", "list each value once")
        return FieldType(kind="enum", values=values)
    if form == "array":
        anode = v["array"]
        items = _field_type(reader, anode, type_names, f"{where}[]")
        return FieldType(kind="array", items=items, min_length=min_len, max_length=max_len)
    tnode = v["type"]
    if not isinstance(tnode.value, str):
        reader.src.at(tnode, f"'type' of '{where}' must be a type name", "e.g. float64")
        return FieldType(kind="string")
    base = _type_expr(reader, tnode.value, tnode, type_names, where=where)
    if (minimum is not None or maximum is not None) and base.kind not in SCALAR_KINDS[:10] + ("time",):
        reader.src.at(node, f"'min'/'max' on '{where}' need a numeric type, not {base.describe()}", "remove them")
    if base.kind == "array":
        return FieldType(kind="array", items=base.items, min_length=min_len, max_length=max_len)
    if min_len is not None or max_len is not None:
        reader.src.at(node, f"'min_length'/'max_length' on '{where}' need an array type", "use {array: T, …}")
    return FieldType(kind=base.kind, ref=base.ref, values=base.values, items=base.items,
                     minimum=minimum, maximum=maximum)


def _type_expr(reader: SpecReader, text: str, node: Node, type_names: list[str], *, where: str) -> FieldType:
    text = text.strip()
    if text.endswith("[]"):
        return FieldType(kind="array", items=_type_expr(reader, text[:-2], node, type_names, where=where + "[]"))
    if text in SCALAR_KINDS:
        return FieldType(kind=text)
    if text in type_names:
        return FieldType(kind="struct", ref=text)
    hint = did_you_mean(text, list(SCALAR_KINDS) + type_names) or (
        "use a scalar kind (" + ", ".join(SCALAR_KINDS) + ") or a declared type")
    reader.src.at(node, f"field '{where}' has unknown type '{text}'", hint)
    return FieldType(kind="string")


def _length(reader: SpecReader, node: Node | None, where: str) -> int | None:
    if node is None:
        return None
    if not isinstance(node.value, int) or isinstance(node.value, bool) or node.value < 0:
        reader.src.at(node, f"length bound of '{where}' must be a whole number ≥ 0", "e.g. max_length: 64")
        return None
    return node.value


def _check_recursion(reader: SpecReader, types: dict[str, MessageType], node: Node) -> None:
    # A struct that contains itself without an array in between can never
    # be a finite message.
    def refs(ft: FieldType) -> list[str]:
        return [ft.ref] if ft.kind == "struct" and ft.ref else []

    for start in types:
        stack, seen = [start], set()
        while stack:
            cur = stack.pop()
            for ft in types.get(cur, MessageType(cur, {})).fields.values():
                for r in refs(ft):
                    if r == start:
                        reader.src.at_key(node, start, f"type '{start}' contains itself",
                                        "break the cycle with an array")
                        stack = []
                        break
                    if r not in seen:
                        seen.add(r)
                        stack.append(r)


def read_brittle_section(reader: SpecReader, node: Node | None, types: dict[str, MessageType]) -> list[str]:
    """The ``Type.field.path`` patterns of fields a generated test case leaves alone."""
    if node is None:
        return []
    if not node.is_list:
        reader.src.at(node, "'brittle' must be a list of 'Type.field' entries", "e.g. [Header.stamp, Header.seq]")
        return []
    out = []
    for item in node.value:
        if not reader.expect(item, (str,), "a brittle entry", "'Type.field.path'"):
            continue
        try:
            check_brittle_pattern(types, item.value)
        except FieldPathError as exc:
            reader.src.report(item.line, item.column + (exc.position or 0), str(exc),
                            "write 'TypeName.field.path' with a type and fields declared under 'types'")
            continue
        out.append(item.value)
    return out
