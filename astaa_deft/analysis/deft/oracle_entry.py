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
from typing import Any

from astaa_deft.model.json import JsonValue


@dataclass(frozen=True)
class OracleEntry:
    """One ``oracles`` entry of a manifest, typed; read with :meth:`from_json`."""

    kind: str  # "collision" | "invariant"
    frame: int | None  # the frame index it judges (None: an entry without one)
    invariant: str | None = None  # kind "invariant": the invariant's name
    start_ns: int = 0  # kind "invariant": the run's start, the clock the invariant is judged on
    snapshot: str | None = None  # the pickled state before ``frame``, relative to the suite's directory
    snapshot_params: JsonValue = None  # the suite params the snapshot was taken with
    snapshot_code: str | None = None  # the module code's fingerprint then (replay.code_fingerprint)

    @classmethod
    def from_json(cls, entry: Mapping[str, Any]) -> OracleEntry:
        """The entry as the manifest holds it (KeyError without ``kind``; the other fields are optional)."""
        of = entry.get("snapshot_of") or {}
        return cls(kind=entry["kind"], frame=entry.get("frame"), invariant=entry.get("invariant"),
                   start_ns=int(entry.get("start_ns", 0)), snapshot=entry.get("snapshot") or None,
                   snapshot_params=of.get("params"), snapshot_code=of.get("code"))
