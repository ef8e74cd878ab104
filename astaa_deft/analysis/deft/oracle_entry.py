"""An oracle test as an exported suite's manifest (DIR/deft.json, ``oracles``) lists it.

Two kinds: ``collision`` (written by the extraction: the planned trajectory
reaches an obstacle the frame's own inputs predicted) and ``invariant``
(written by ``astaa-deft minimise``: the replayed outputs break an
invariant). A collision oracle may carry a snapshot of the module's state
just before its frame (snapshots.py), with what it was taken from.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TypeVar

from astaa_deft.model.json import JsonObject, JsonValue

T = TypeVar("T")
# The two kinds of oracle entry (``OracleEntry.kind``).
COLLISION, INVARIANT = "collision", "invariant"
_KINDS: dict[type, str] = {str: "a string", int: "an integer", dict: "an object"}


@dataclass(frozen=True, kw_only=True)
class OracleEntry:
    """One ``oracles`` entry of a manifest, typed; read with :meth:`from_json`."""

    kind: str  # COLLISION | INVARIANT
    frame: int | None  # the frame index it judges (None: an entry without one)
    invariant: str | None = None  # kind "invariant": the invariant's name
    start_ns: int = 0  # kind "invariant": the run's start, the clock the invariant is judged on
    snapshot: str | None = None  # the pickled state before ``frame``, relative to the suite's directory
    snapshot_params: JsonValue = None  # the suite params the snapshot was taken with
    snapshot_code: str | None = None  # the module code's fingerprint then (replay.code_fingerprint)

    @classmethod
    def from_json(cls, entry: JsonObject) -> OracleEntry:
        """The entry as the manifest holds it (KeyError without ``kind``; the other fields are optional;
        ValueError naming the field for a value of another type)."""
        of = _optional(entry, "snapshot_of", dict) or {}
        start = entry.get("start_ns", 0)
        if not isinstance(start, (int, float, str)):
            raise _wrong("start_ns", start, "a number")
        return cls(kind=_required(entry, "kind", str), frame=_optional(entry, "frame", int),
                   invariant=_optional(entry, "invariant", str), start_ns=int(start),
                   snapshot=_optional(entry, "snapshot", str) or None, snapshot_params=of.get("params"),
                   snapshot_code=_optional(of, "code", str))


def _required(entry: Mapping[str, JsonValue], key: str, kind: type[T]) -> T:
    value = entry[key]
    if not isinstance(value, kind):
        raise _wrong(key, value, _KINDS[kind])
    return value


def _optional(entry: Mapping[str, JsonValue], key: str, kind: type[T]) -> T | None:
    value = entry.get(key)
    if value is not None and not isinstance(value, kind):
        raise _wrong(key, value, f"{_KINDS[kind]} or null")
    return value


def _wrong(key: str, value: JsonValue, expected: str) -> ValueError:
    return ValueError(f"a manifest's oracle entry: '{key}' is {str(value)[:60]!r}, not {expected}")
