"""Read a test log, including one whose writer was killed before finishing.

The streaming reader is used on purpose: it needs no summary section, so a
truncated file yields every complete chunk and then stops at the cut; we
turn the cut into a warning instead of an exception.
"""

from __future__ import annotations

import json
import struct
import zlib
from dataclasses import dataclass, field
from typing import BinaryIO, ClassVar, Protocol, TypeVar
from pathlib import Path

from mcap.exceptions import EndOfFile, InvalidMagic
from mcap.opcode import Opcode
from mcap.records import (Attachment, Channel, Chunk, DataEnd, Footer, McapRecord, Message, MessageIndex, Metadata,
                          Schema, Statistics)
from mcap.stream_reader import StreamReader, breakup_chunk

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.inputfile import LOG, open_input
from astaa_deft.io.log import layout
from astaa_deft.io.log import records as rec


class _Kinded(Protocol):
    kind: ClassVar[str]


R = TypeVar("R", bound=_Kinded)  # a record type of log/records.py (each names its event kind)

MCAP_MAGIC = b"\x89MCAP0\r\n"


@dataclass(frozen=True)
class LoggedMessage:
    topic: str
    log_time: int
    publish_time: int
    sequence: int
    data: bytes


@dataclass(kw_only=True)
class ChannelInfo:
    id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]
    schema_name: str = ""


@dataclass(kw_only=True)
class LogContents:
    """Everything in a log, read in one pass."""

    path: Path
    channels: dict[str, ChannelInfo] = field(default_factory=dict)
    messages: list[LoggedMessage] = field(default_factory=list)
    attachments: dict[str, bytes] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    finished: bool = False  # the writer reached finish() (footer present)
    warnings: list[str] = field(default_factory=list)
    damage: list[str] = field(default_factory=list)  # what could not be read, and where (also in warnings)
    truncated: bool = False  # the file stops early (a writer killed mid-run), as opposed to damage inside it
    damaged_chunks: list[tuple[int, int]] = field(default_factory=list)  # (start, end) log times, ns
    statistics: Statistics | None = None
    size: int = 0
    _orphans: dict[int, list[Message]] = field(default_factory=dict, repr=False)
    data_crc: tuple[int, int] = (0, 0)
    _schema_names: dict[int, str] = field(default_factory=dict, repr=False)
    _topic_by_id: dict[int, str] = field(default_factory=dict, repr=False)

    @property
    def intact(self) -> bool:
        """Finished, nothing damaged, and as many messages read as the log says it holds."""
        return self.finished and not self.damage

    def note_damage(self, text: str, truncated: bool = False) -> None:
        self.damage.append(text)
        self.warnings.append(text)
        self.truncated = self.truncated or truncated

    def describe_reading(self) -> str:
        """What was read, for a verdict that cannot be given on an incomplete record."""
        claimed = f" of {self.statistics.message_count} the log counts" if self.statistics is not None else ""
        return (f"read {len(self.messages)} messages{claimed} on {len(self.channels)} channels from "
                f"{self.size:,} bytes")

    def on(self, topic: str) -> list[LoggedMessage]:
        return [m for m in self.messages if m.topic == topic]

    def events(self, kind: str | None = None) -> list[dict]:
        out = []
        for m in self.on(layout.EVENTS_TOPIC):
            body = _json_object(m.data)
            if body is None:
                continue  # an event that does not decode is damage, counted by unreadable_events()
            if kind is None or body.get("kind") == kind:
                out.append(body)
        return out

    def records(self, kind: type[R]) -> list[R]:
        """The tool's events of one record type (``log/records.py``), typed."""
        bodies = self.events(kind.kind)
        return [r for r in (rec.decode(b, where=str(self.path)) for b in bodies) if isinstance(r, kind)]

    def unreadable_events(self) -> int:
        return sum(_json_object(m.data) is None for m in self.on(layout.EVENTS_TOPIC))

    def flags(self) -> list[dict]:
        return [body for m in self.on(layout.FLAGS_TOPIC) if (body := _json_object(m.data)) is not None]

    def bus_topics(self) -> list[str]:
        return [t for t in self.channels if not t.startswith("/astaa/")]


def read_log(path: Path | str) -> LogContents:
    """Every readable record of the MCAP log at ``path``, with what could not be read in ``damage``.

    Raises InputError for a path that is not a log file at all: missing, a
    directory, not a regular file (a device such as /dev/zero, a pipe),
    empty, or not MCAP. A log that was cut, damaged inside, or followed by
    other data is returned with its damage noted (``intact`` False).
    """
    path = Path(path)
    stream = open_input(path, LOG)  # a regular file, or InputError; closed by the `with` below
    out = LogContents(path=path)
    size = path.stat().st_size
    out.size = size
    if size == 0:
        stream.close()
        raise InputError(Problem(str(path), None, None, "the log is empty (nothing was ever written to it)",
                                 "record a run first: astaa-deft proxy --spec SPEC --record FILE"))
    with stream:
        _read_all(out, stream, size)
    _adopt_orphans(out)
    _compare_with_summary(out)
    if not out.finished and not out.damage:
        out.note_damage(f"{path}: the log was not finished cleanly (no footer); all complete chunks were read",
                        truncated=True)
    return out


def _read_all(out: LogContents, stream: BinaryIO, size: int) -> None:
    """Every record of the file; a damaged chunk is skipped and reported, a damaged record stops the read."""
    path = out.path
    if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
        raise InputError(Problem(str(path), None, None, "not an MCAP file (its first bytes are not the MCAP magic)",
                                 "give a log written by astaa-deft"))
    stream.seek(0)
    reader = StreamReader(stream, emit_chunks=True, record_size_limit=max(size, 1 << 10))
    records = reader.records
    data_end_offset = None
    last_chunk: _ChunkContent | None = None
    while True:
        offset = max(stream.tell(), len(MCAP_MAGIC))
        try:
            record = next(records)
        except StopIteration:
            _check_nothing_follows(out, stream, size)
            break
        except InvalidMagic:
            out.note_damage(f"{path}: the log's closing magic is damaged (byte {offset:,}); "
                            f"everything before it was read")
            break
        except EndOfFile:
            if _ends_with_magic(stream, size):
                out.note_damage(f"{path}: damaged at byte {offset:,} of {size:,}: a record there claims more bytes "
                                f"than the file holds; kept {len(out.messages)} messages read before it")
            else:
                out.note_damage(f"{path}: the log ends early (cut at byte {size:,}, inside a record that starts at "
                                f"byte {offset:,}); kept {len(out.messages)} messages from the complete chunks "
                                f"before the cut", truncated=True)
            break
        except Exception as exc:  # the mcap library raises several types for a damaged record
            out.note_damage(f"{path}: damaged at byte {offset:,} of {size:,} ({_plain(exc)}); "
                            f"kept {len(out.messages)} messages read before it, the rest of the file was not read")
            break
        if isinstance(record, Chunk):
            last_chunk = _take_chunk(out, record, offset)
        elif isinstance(record, MessageIndex):
            _check_index(out, record, last_chunk)
        elif isinstance(record, Footer):
            _check_summary(out, record, stream, offset)
            _take(out, record, offset)
        elif isinstance(record, DataEnd):
            data_end_offset = offset
            out.data_crc = (record.data_section_crc, offset)
        else:
            _take(out, record, offset)
    if data_end_offset is not None and out.data_crc[0] != 0 and not out.damage:
        actual = _crc_of_prefix(stream, data_end_offset)
        if actual != out.data_crc[0]:
            out.note_damage(f"{path}: the data section fails its CRC check (damage outside the message chunks: "
                            f"in schemas, channels, attachments or metadata)")


def _take_chunk(out: LogContents, chunk: Chunk, offset: int) -> _ChunkContent | None:
    reason = ""
    raw = b""
    if chunk.uncompressed_size > MAX_CHUNK_BYTES:
        reason = f"it claims {chunk.uncompressed_size:,} bytes of content"
    else:
        try:
            raw = _decompress(chunk)
        except Exception as exc:  # zstd/lz4 report corrupt frames with their own types
            reason = f"its content cannot be decompressed ({_plain(exc)})"
    if not reason and len(raw) != chunk.uncompressed_size:
        reason = f"its header claims {chunk.uncompressed_size:,} bytes of content, it holds {len(raw):,}"
    if not reason and chunk.uncompressed_crc != 0 and zlib.crc32(raw) != chunk.uncompressed_crc:
        reason = "its CRC does not match its content"
    records: list = []
    if not reason:
        try:
            records = breakup_chunk(Chunk(compression="", data=raw, message_start_time=chunk.message_start_time,
                                          message_end_time=chunk.message_end_time,
                                          uncompressed_size=len(raw), uncompressed_crc=0))
        except Exception as exc:
            reason = f"its records cannot be read ({_plain(exc)})"
    times = [r.log_time for r in records if isinstance(r, Message)]
    if not reason and times and (min(times) != chunk.message_start_time or max(times) != chunk.message_end_time):
        reason = "its header's time range does not match its messages"
    if reason:
        out.damaged_chunks.append((chunk.message_start_time, chunk.message_end_time))
        out.note_damage(f"{out.path}: chunk at byte {offset:,} (log time {_when(chunk.message_start_time)} to "
                        f"{_when(chunk.message_end_time)} by its header) is damaged: {reason}; "
                        f"its messages were not read")
        return None
    for record in records:
        _take(out, record, offset)
    return _ChunkContent(raw, offset)


@dataclass
class _ChunkContent:
    raw: bytes  # the uncompressed records: a message index points into these
    offset: int  # of the chunk record in the file


def _decompress(chunk: Chunk) -> bytes:
    if chunk.compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    if chunk.compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(chunk.data)
    if chunk.compression == "":
        return bytes(chunk.data)
    raise ValueError(f"unknown compression '{chunk.compression[:20]}'")


def _check_index(out: LogContents, index: MessageIndex, chunk: _ChunkContent | None) -> None:
    """The index after a chunk points at each of its messages; an index that does not is damage an indexed
    reader (Foxglove) would trip on, though our own streaming read does not need it."""
    if chunk is None:
        return  # the chunk itself was reported
    for log_time, position in index.records:
        head = chunk.raw[position:position + _MESSAGE_HEAD.size]
        fields = _MESSAGE_HEAD.unpack(head) if len(head) == _MESSAGE_HEAD.size else None
        if fields is None or (fields[0], fields[2], fields[4]) != (Opcode.MESSAGE, index.channel_id, log_time):
            out.note_damage(f"{out.path}: the message index of the chunk at byte {chunk.offset:,} does not point "
                            f"at its messages (damaged index); the messages themselves were read")
            return


# opcode, record length, channel id, sequence, log time
_MESSAGE_HEAD = struct.Struct("<BQHIQ")
MAX_CHUNK_BYTES = 1 << 28


def _check_nothing_follows(out: LogContents, stream: BinaryIO, size: int) -> None:
    """The log ends at its closing magic; bytes after it (a second log written into the file, junk, text
    appended) are part of the evidence that was not read, so the log is damaged, never clean."""
    end = stream.tell()
    if end >= size:
        return
    stream.seek(end)
    head = stream.read(len(MCAP_MAGIC))
    what = ("another MCAP log starts there (a second run written into the same file)" if head == MCAP_MAGIC
            else "they are not part of this log (data appended to the file)")
    out.note_damage(f"{out.path}: {size - end:,} bytes follow the log's end (its closing magic at byte "
                    f"{end - len(MCAP_MAGIC):,}): {what}; they were not read")


def _check_summary(out: LogContents, footer: Footer, stream: BinaryIO, footer_offset: int) -> None:
    """The footer's CRC covers the summary section (its channel list, statistics and indexes)."""
    if footer.summary_crc == 0 or footer.summary_start == 0 or footer.summary_start > footer_offset:
        return
    here = stream.tell()
    stream.seek(footer.summary_start)
    covered = stream.read(footer_offset + 25 - footer.summary_start)
    stream.seek(here)
    if zlib.crc32(covered) != footer.summary_crc:
        out.note_damage(f"{out.path}: the summary section (from byte {footer.summary_start:,}) fails its CRC check; "
                        f"its statistics and indexes cannot be trusted")


def _adopt_orphans(out: LogContents) -> None:
    """Messages whose channel was declared only in a damaged chunk: kept if the summary declares it."""
    if not out._orphans:
        return
    lost = 0
    for channel_id, records in out._orphans.items():
        topic = out._topic_by_id.get(channel_id)
        if topic is None:
            lost += len(records)
            continue
        out.messages.extend(LoggedMessage(topic, r.log_time, r.publish_time, r.sequence, bytes(r.data))
                            for r in records)
    out.messages.sort(key=lambda m: m.log_time)
    if lost:
        out.note_damage(f"{out.path}: {lost} messages name channels the log never declared (their declaration "
                        f"was damaged); they were not read")


def _compare_with_summary(out: LogContents) -> None:
    """A finished log says how many messages it holds; reading fewer means we did not see the whole run."""
    stats = out.statistics
    if stats is None:
        return
    if stats.message_count != len(out.messages) and not out.damaged_chunks:
        out.note_damage(f"{out.path}: read {len(out.messages)} messages but the log's summary counts "
                        f"{stats.message_count}")


def _ends_with_magic(stream: BinaryIO, size: int) -> bool:
    if size < 8:
        return False
    stream.seek(size - 8)
    return stream.read(8) == MCAP_MAGIC


def _crc_of_prefix(stream: BinaryIO, length: int) -> int:
    stream.seek(0)
    crc, left = 0, length
    while left > 0:
        block = stream.read(min(left, 1 << 20))
        if not block:
            break
        crc = zlib.crc32(block, crc)
        left -= len(block)
    return crc


def _json_object(data: bytes) -> dict | None:
    try:
        body = json.loads(data)
    except (ValueError, RecursionError):  # not UTF-8 or not JSON
        return None
    return body if isinstance(body, dict) else None


def _when(ns: int) -> str:
    return f"{ns / 1e9:.3f} s"


def _plain(exc: BaseException) -> str:
    """The library's message without its internal exception class name."""
    if isinstance(exc, struct.error):
        return "a record is cut short or malformed"
    text = str(exc).strip()
    return text[:200] if text else "unreadable record"


def _take(out: LogContents, record: McapRecord, offset: int = 0) -> None:
    if isinstance(record, Schema):
        out._schema_names[record.id] = record.name
    elif isinstance(record, Channel):
        if record.topic not in out.channels:
            schema_name = out._schema_names.get(record.schema_id, "")
            out.channels[record.topic] = ChannelInfo(id=record.id, topic=record.topic,
                                                     message_encoding=record.message_encoding,
                                                     metadata=dict(record.metadata), schema_name=schema_name)
            out._topic_by_id[record.id] = record.topic
    elif isinstance(record, Message):
        topic = out._topic_by_id.get(record.channel_id)
        if topic is None:  # declared in a damaged chunk, perhaps; the summary section declares it again
            out._orphans.setdefault(record.channel_id, []).append(record)
            return
        out.messages.append(LoggedMessage(topic, record.log_time, record.publish_time, record.sequence,
                                          bytes(record.data)))
    elif isinstance(record, Attachment):
        out.attachments[record.name] = bytes(record.data)
    elif isinstance(record, Metadata):
        out.metadata[record.name] = dict(record.metadata)
    elif isinstance(record, Statistics):
        out.statistics = record
    elif isinstance(record, Footer):
        out.finished = True
