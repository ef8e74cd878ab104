"""Read a test log, including one whose writer was killed before finishing.

The streaming reader is used on purpose: it needs no summary section, so a
truncated file yields every complete chunk and then stops at the cut; we
turn the cut into a warning instead of an exception.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

from mcap.reader import StreamReader
from mcap.records import Attachment, Channel, Footer, Message, Metadata, Schema

from ..errors import InputError, Problem
from . import layout


@dataclass(frozen=True)
class LoggedMessage:
    topic: str
    log_time: int
    publish_time: int
    sequence: int
    data: bytes


@dataclass
class ChannelInfo:
    id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]
    schema_name: str = ""


@dataclass
class LogContents:
    """Everything in a log, read in one pass."""

    path: Path
    channels: dict[str, ChannelInfo] = field(default_factory=dict)
    messages: list[LoggedMessage] = field(default_factory=list)
    attachments: dict[str, bytes] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    finished: bool = False  # the writer reached finish() (footer present)
    warnings: list[str] = field(default_factory=list)
    _schema_names: dict[int, str] = field(default_factory=dict, repr=False)
    _topic_by_id: dict[int, str] = field(default_factory=dict, repr=False)

    def on(self, topic: str) -> list[LoggedMessage]:
        return [m for m in self.messages if m.topic == topic]

    def events(self, kind: str | None = None) -> list[dict]:
        out = []
        for m in self.on(layout.EVENTS_TOPIC):
            body = json.loads(m.data)
            if kind is None or body.get("kind") == kind:
                out.append(body)
        return out

    def flags(self) -> list[dict]:
        return [json.loads(m.data) for m in self.on(layout.FLAGS_TOPIC)]

    def bus_topics(self) -> list[str]:
        return [t for t in self.channels if not t.startswith("/astaa/")]


def read_log(path: Path | str) -> LogContents:
    path = Path(path)
    try:
        stream = open(path, "rb")
    except FileNotFoundError:
        raise InputError(Problem(str(path), None, None, "log file not found", "check the path")) from None
    except OSError as exc:
        raise InputError(Problem(str(path), None, None, f"cannot read log: {exc.strerror}", "")) from None
    out = LogContents(path)
    if path.stat().st_size == 0:
        stream.close()
        raise InputError(Problem(str(path), None, None, "the log is empty (nothing was ever written to it)",
                                 "record a run first: astaa-deft proxy --spec SPEC --record FILE"))
    with stream:
        try:
            for record in _records(stream):
                _take(out, record)
        except InputError:
            raise
        except Exception as exc:  # the mcap library raises several types at a cut
            read = len(out.messages)
            out.warnings.append(
                f"{path}: the log ends early ({type(exc).__name__}: {exc}); "
                f"kept {read} messages from the complete chunks before the cut"
            )
    if not out.finished and not out.warnings:
        out.warnings.append(f"{path}: the log was not finished cleanly (no footer); all complete chunks were read")
    return out


def _records(stream) -> Iterator:
    try:
        reader = StreamReader(stream, record_size_limit=1 << 30)
        records = reader.records
        yield from records
    except Exception as exc:
        if stream.tell() <= 8:
            raise InputError(Problem(str(getattr(stream, "name", "?")), None, None,
                                     f"not an MCAP file ({exc})", "give a log written by astaa-deft")) from None
        raise


def _take(out: LogContents, record) -> None:
    if isinstance(record, Schema):
        out._schema_names[record.id] = record.name
    elif isinstance(record, Channel):
        if record.topic not in out.channels:
            schema_name = out._schema_names.get(record.schema_id, "")
            out.channels[record.topic] = ChannelInfo(record.id, record.topic, record.message_encoding,
                                                     dict(record.metadata), schema_name)
            out._topic_by_id[record.id] = record.topic
    elif isinstance(record, Message):
        topic = out._topic_by_id[record.channel_id]
        out.messages.append(LoggedMessage(topic, record.log_time, record.publish_time, record.sequence,
                                          bytes(record.data)))
    elif isinstance(record, Attachment):
        out.attachments[record.name] = bytes(record.data)
    elif isinstance(record, Metadata):
        out.metadata[record.name] = dict(record.metadata)
    elif isinstance(record, Footer):
        out.finished = True
