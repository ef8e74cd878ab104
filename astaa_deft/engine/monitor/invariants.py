"""The spec's ``invariants:`` section: validated, typed invariants.

``build_invariants`` is what the spec loader calls; each kind's own fields
and checks live in ``kinds/<kind>.py``. Problems are reported through the
spec's ``Source`` with line, column and a fix, and the invariants that are
valid are returned, so one ``spec check`` lists every mistake.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence

from astaa_deft.model.records import Verdict
from astaa_deft.model.errors import did_you_mean
from astaa_deft.model.sut import Channel, MessageType, Spec
from astaa_deft.io.yamlsource import Node, Source
from astaa_deft.engine.monitor.base import Invariant
from astaa_deft.engine.monitor.kinds import KINDS
from astaa_deft.engine.monitor.kinds.bound import BoundInvariant
from astaa_deft.engine.monitor.kinds.collision import CollisionInvariant, Footprint
from astaa_deft.engine.monitor.kinds.deadline import DeadlineInvariant
from astaa_deft.engine.monitor.kinds.expression import ExpressionInvariant
from astaa_deft.engine.monitor.kinds.process import ProcessInvariant
from astaa_deft.engine.monitor.kinds.temporal import Signal, TemporalInvariant
from astaa_deft.engine.monitor.spec_reader import InvariantReader
from astaa_deft.engine.monitor.violation import CRASH_CLASSES, SEVERITIES

__all__ = [
    "Invariant", "BoundInvariant", "CollisionInvariant", "DeadlineInvariant", "ExpressionInvariant",
    "Footprint", "ProcessInvariant", "Signal", "TemporalInvariant", "build_invariants", "with_typed_invariants",
]

COMMON_KEYS = ("name", "kind", "severity", "crash", "description")
DEFAULT_SEVERITY = "high"


def build_invariants(src: Source, node: Node | None, types: Mapping[str, MessageType],
                     channels: Sequence[Channel], *, modules: Sequence[str]) -> tuple[Invariant, ...]:
    if node is None or node.value is None:
        return ()
    if not node.is_list:
        src.at(node, "'invariants' must be a list", "write each invariant as '- {name: …, kind: …}'")
        return ()
    reader = InvariantReader(src, types, channels, modules)
    out: list[Invariant] = []
    names: set[str] = set()
    for item in node.value:
        invariant = _one(reader, item)
        if invariant is None:
            continue
        if invariant.name in names:
            src.at(item, f"invariant '{invariant.name}' is declared twice", "give each invariant a unique name")
            continue
        names.add(invariant.name)
        out.append(invariant)
    return tuple(out)


def _one(reader: InvariantReader, item: Node) -> Invariant | None:
    if not item.is_map:
        reader.problem(item, "an invariant must be a mapping", "e.g. - {name: speed_ok, kind: bound, …}")
        return None
    v = item.value
    kind = reader.choice(v.get("kind"), "'kind'", tuple(KINDS)) if "kind" in v else None
    allowed = COMMON_KEYS + (KINDS[kind].keys if kind else tuple(k for spec in KINDS.values() for k in spec.keys))
    required = ("name", "kind") + (KINDS[kind].required if kind else ())
    what = f"invariant '{v['name'].value}'" if "name" in v and isinstance(v["name"].value, str) else "an invariant"
    keys_ok = reader.keys(item, allowed, required, what)
    name = reader.name(v["name"], "invariant name") if "name" in v else None
    severity = reader.choice(v.get("severity"), "'severity'", SEVERITIES) if "severity" in v else DEFAULT_SEVERITY
    crash = _crash(reader, v.get("crash"))
    description = reader.text(v.get("description"), "'description'", "what the invariant protects") or ""
    if not keys_ok or kind is None or name is None or severity is None or crash is False:
        return None
    common = {"name": name, "severity": severity, "crash": crash or None, "description": description,
              "line": item.line}
    return KINDS[kind].parse(reader, item, common)


def _crash(reader: InvariantReader, node: Node | None) -> Verdict | None | bool:
    """The CRASH class an invariant's violations point at (None: its kind's default; False: invalid)."""
    if node is None:
        return None
    text = node.value if isinstance(node.value, str) else ""
    match = next((c for c in CRASH_CLASSES if c.lower() == text.lower()), None)
    if match is None:
        hint = did_you_mean(text.capitalize(), CRASH_CLASSES) or f"one of: {', '.join(CRASH_CLASSES)}"
        reader.problem(node, f"'crash' must be one of {', '.join(CRASH_CLASSES)}", hint)
        return False
    return match


def with_typed_invariants(spec: Spec, source_name: str | None = None) -> Spec:
    """``spec`` with its ``invariants`` built from its YAML, if the loader left them raw.

    The spec loader calls ``build_invariants`` itself; this covers a spec
    loaded without it (e.g. by an older loader), so monitors always see
    typed invariants. Raises InputError on a malformed invariant; problems
    name ``source_name`` (default: the spec's path).
    """
    if all(isinstance(i, Invariant) for i in spec.invariants):
        return spec
    src = Source(spec.source_text, source_name or (str(spec.path) if spec.path else "<spec>"))
    root = src.parse()
    node = root.value.get("invariants") if root.is_map else None
    invariants = build_invariants(src, node, spec.types, spec.channels, modules=[m.name for m in spec.modules])
    src.raise_if_problems()
    return dataclasses.replace(spec, invariants=invariants)
