"""The replayed module's recorded traffic: inputs and outputs in log order, decoded once.

Also what an output says about itself: the inputs it names as used (the
spec's ``provenance``), a frame tried first when it does.
"""

from __future__ import annotations

import functools

from bisect import bisect_right
from collections.abc import Mapping
from dataclasses import dataclass, field
from itertools import pairwise

from astaa_deft.analysis.deft.frames import Candidate, Stream
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.io.codecs import get_codec
from astaa_deft.io.codecs.base import Codec, DecodeError
from astaa_deft.io.log import records as rec
from astaa_deft.io.log.reader import LogContents, LoggedMessage
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.json import DecodedMessage
from astaa_deft.model.sut import Spec


def channel_messages(log: LogContents, spec: Spec, names: list[str]) -> dict[str, list[LoggedMessage]]:
    out: dict[str, list[LoggedMessage]] = {}
    for name in names:
        key = spec.channel(name).key
        if key not in log.channels:
            raise InputError(Problem(str(log.path), None, None,
                                     f"the log has no channel '{name}' (key '{key}')",
                                     "record the run with this spec, or check that the log belongs to it"))
        out[name] = sorted(log.on(key), key=lambda m: m.log_time)
    return out


def log_start(log: LogContents) -> int:
    return min((m.log_time for key in log.channels for m in log.on(key)), default=0)


def recorded_cycle_s(recorded: Recorded, index: int) -> float:
    """The time the recorded planner took for this output: the gap since its previous one (or the median)."""
    outputs, median = recorded.outputs, recorded.median_output_gap_s
    if index == 0:
        return median
    return max(median, (outputs[index].log_time - outputs[index - 1].log_time) * 1e-9)


@dataclass
class Recorded:
    """The replayed module's recorded traffic: its inputs (decoded on demand, once) and outputs, in log order."""

    messages: dict[str, list[LoggedMessage]]  # input channel → its messages
    outputs: list[LoggedMessage]
    streams: dict[str, Stream]
    codecs: dict[str, Codec]
    index_of: dict[str, dict[int, int]]  # input channel → id(message) → its index in ``messages``
    decoded: dict[tuple[str, int], DecodedMessage | None] = field(default_factory=dict)
    module_started_in_log: bool = False  # the run's start is logged before the module's first trigger

    @classmethod
    def read(cls, log: LogContents, spec: Spec, cfg: ReplayModule) -> Recorded:
        """Raises InputError when the log lacks one of the module's channels."""
        messages = channel_messages(log, spec, list(cfg.inputs) + [cfg.output])
        outputs = messages.pop(cfg.output)
        started = [r.time_ns for r in log.records(rec.RunStarted)]
        triggers = messages[cfg.trigger]
        return cls(messages=messages, outputs=outputs,
                   module_started_in_log=bool(started and triggers and started[0] <= triggers[0].log_time),
                   streams={name: Stream(name, [m.log_time for m in msgs]) for name, msgs in messages.items()},
                   codecs={name: get_codec(spec.channel(name).encoding) for name in list(cfg.inputs) + [cfg.output]},
                   index_of={name: {id(msg): i for i, msg in enumerate(msgs)} for name, msgs in messages.items()})

    @functools.cached_property
    def median_output_gap_s(self) -> float:
        """The median time between two recorded outputs (0 for fewer than two): computed once, not per output."""
        gaps = sorted(b.log_time - a.log_time for a, b in pairwise(self.outputs))
        return gaps[len(gaps) // 2] * 1e-9 if gaps else 0.0

    def declared(self, cfg: ReplayModule, output_message: object, previous: Mapping[str, int], until: int
                 ) -> Candidate | None:
        """The frame the output says it used (``cfg.provenance``: {input: its header.seq or header.stamp}; an
        input it names with null, or not at all, was absent), or None when the output names none we have."""
        named = provenance_of(output_message, cfg.provenance)
        if named is None:
            return None
        choice: dict[str, int] = {}
        for name in cfg.inputs:
            if named.get(name) is None:
                if name == cfg.trigger:
                    return None
                continue
            times = self.streams[name].times
            newest = bisect_right(times, until) - 1
            found = next((i for i in range(newest, previous.get(name, 0) - 1, -1)
                          if names_message(self.decode(name, i), named[name])), None)
            if found is None:
                return None
            choice[name] = found
        return Candidate(frame_time=self.streams[cfg.trigger].times[choice[cfg.trigger]], choice=choice,
                         patterns=frozenset({(DECLARED, ())}))

    def fresh(self, name: str, idx: int) -> DecodedMessage | None:
        """Message ``idx`` of input ``name`` decoded anew (None if it does not decode): what a module steps on
        gets its own objects, as in the suite's run (a module may change its inputs in place)."""
        if self.decode(name, idx) is None:
            return None
        return self.codecs[name].decode(self.messages[name][idx].data)

    def frame(self, choice: Mapping[str, int], *, fresh: bool = False) -> dict[str, DecodedMessage | None]:
        """The inputs ``choice`` names, each decoded (anew when ``fresh``, see :meth:`fresh`; None: it does not
        decode)."""
        read = self.fresh if fresh else self.decode
        return {name: read(name, idx) for name, idx in choice.items()}

    def decode(self, name: str, idx: int) -> DecodedMessage | None:
        """Message ``idx`` of input ``name`` decoded, or None if it does not decode."""
        k = (name, idx)
        if k not in self.decoded:
            try:
                self.decoded[k] = self.codecs[name].decode(self.messages[name][idx].data)
            except DecodeError:
                self.decoded[k] = None
        return self.decoded[k]


DECLARED = "declared"  # a frame the module's own output names (provenance)


def provenance_of(message: object, path: str | None) -> Mapping[str, object] | None:
    """The inputs an output names as used (``path``: the spec's ``provenance``), or None."""
    from astaa_deft.model.fields import get

    if path is None or message is None:
        return None
    found = get(message, path)
    return found[0][1] if found and isinstance(found[0][1], Mapping) else None


def names_message(message: object, named: object) -> bool:
    """Is ``message`` the one an output names by ``named`` (its header.seq, or its header.stamp)?"""
    header = message.get("header") if isinstance(message, Mapping) else None
    if not isinstance(header, Mapping):
        return False
    if isinstance(named, bool):
        return False
    if isinstance(named, int) and header.get("seq") == named:
        return True
    return header.get("stamp") == named
