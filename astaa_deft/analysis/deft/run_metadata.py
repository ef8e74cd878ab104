"""The description of a run its recorder stores in the log (MCAP metadata ``astaa-deft.run``)."""

from __future__ import annotations

from dataclasses import dataclass, field

from astaa_deft.io.log import layout
from astaa_deft.io.log.reader import LogContents
from astaa_deft.io.statefile import StateReader, load_json


@dataclass(frozen=True)
class RunMetadata:
    """Which spec the run was recorded with and the params that filled its placeholders.

    A log without the record (or with a field missing) reads as unknown
    spec and no params (a replay builds the module with the spec's
    defaults). Params that are there but not a JSON object of strings are
    an InputError naming the log and the field (``io/statefile.py``): a
    replay with other params than the run's would not be the run.
    """

    spec: str | None = None  # the spec's name
    params: dict[str, str] = field(default_factory=dict)

    @classmethod
    def of(cls, log: LogContents) -> RunMetadata:
        meta = log.metadata.get(layout.RUN_METADATA, {})
        spec = meta.get("spec")  # the decoder of this record: a missing field reads as unknown
        if "params" not in meta:
            return cls(spec or None, {})
        where, field = str(log.path), f"metadata {layout.RUN_METADATA}: params"
        fix = "re-record the run (the log's record of its params is damaged), or give the params to use"
        params = StateReader(where, load_json(str(meta["params"]), where, field, fix, max_chars=1 << 20), fix,
                             field=field)
        return cls(spec or None, params.map(lambda value: value.string(10_000), max_items=10_000))
