"""The description of a run its recorder stores in the log (MCAP metadata ``astaa-deft.run``)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field

from astaa_deft.io.log import layout
from astaa_deft.io.log.reader import LogContents


@dataclass(frozen=True)
class RunMetadata:
    """Which spec the run was recorded with and the params that filled its placeholders.

    A log without the record (or with a field missing) reads as unknown
    spec and no params; params that are not a JSON object of strings read
    as none, so a replay builds the module with the spec's defaults.
    """

    spec: str | None = None  # the spec's name
    params: dict[str, str] = field(default_factory=dict)

    @classmethod
    def of(cls, log: LogContents) -> RunMetadata:
        meta = log.metadata.get(layout.RUN_METADATA, {})
        spec = meta.get("spec")  # the decoder of this record: a missing field reads as unknown
        try:
            params = json.loads(meta["params"]) if "params" in meta else {}
        except ValueError:
            params = {}
        if not isinstance(params, dict):
            params = {}
        return cls(spec or None, params)
