"""An MCAP writer with a cheap per-message path: the bytes of ``mcap.writer.Writer``, at a tenth of its cost.

``mcap``'s writer builds a dataclass, a dozen small writes and an index
entry per message (most of what the recorder spent per message:
docs/performance.md, "The log writer"). Here a message is one ``struct`` pack appended to the
open chunk; message indexes are packed once per chunk. Every other record
(header, schemas, channels, chunks, attachments, metadata, the summary)
is written by ``mcap``'s own record classes, in the same order and with the
same options the tool used (chunked, ZSTD or none, every index, statistics,
summary offsets, CRCs of chunks, summary and data section), so a log is
byte for byte what ``mcap.writer.Writer`` would have written
(``tests/test_log.py`` compares the two).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterable
from typing import BinaryIO

import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.records import (
    Attachment, AttachmentIndex, Channel, Chunk, ChunkIndex, DataEnd, Footer, Header, McapRecord, Metadata,
    MetadataIndex, Schema, Statistics, SummaryOffset,
)

MAGIC = struct.pack("<8B", 137, 77, 67, 65, 80, 48, 13, 10)
_MESSAGE = struct.Struct("<BQHIQQ")  # opcode, record length, channel id, sequence, log time, publish time
_MESSAGE_BODY = _MESSAGE.size - 9  # the fixed part of a message record after opcode and length
_INDEX_HEAD = struct.Struct("<BQHI")  # opcode, record length, channel id, length of the (time, offset) array


class McapWriter:
    """Writes one MCAP file to ``stream`` (an open binary file); see the module doc."""

    def __init__(self, stream: BinaryIO, chunk_size: int, compression: str = "zstd",
                 enable_data_crcs: bool = True):
        if compression not in ("zstd", ""):
            raise ValueError(f"unsupported compression {compression!r}")
        self._stream = stream
        self._chunk_size = chunk_size
        self._compression = compression
        self._data_crcs = enable_data_crcs
        self._data_crc = 0
        # One compression context for every chunk: the bytes of zstandard.compress(data) (which builds
        # a ZstdCompressor(level=3) per call, as mcap's writer does), without building one per chunk.
        self._compressor = zstandard.ZstdCompressor(level=3)
        self._records = RecordBuilder()  # records outside chunks, until flushed
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._chunk_indexes: list[ChunkIndex] = []
        self._attachment_indexes: list[AttachmentIndex] = []
        self._metadata_indexes: list[MetadataIndex] = []
        # The open chunk: its records, and per channel the (log time, offset) of its messages.
        self._chunk = bytearray()
        self._chunk_messages = 0
        self._chunk_start = 0
        self._chunk_end = 0
        self._chunk_index: dict[int, list[int]] = {}  # channel id → flat [time, offset, time, offset, ...]
        # Statistics.
        self._message_count = 0
        self._message_start = 0
        self._message_end = 0
        self._channel_counts: dict[int, int] = {}
        self._chunk_count = 0
        self._attachment_count = 0
        self._metadata_count = 0

    # -- records ------------------------------------------------------------
    def start(self, profile: str, library: str) -> None:
        self._stream.write(MAGIC)
        if self._data_crcs:
            self._data_crc = zlib.crc32(MAGIC, self._data_crc)
        Header(profile, library).write(self._records)
        self._flush()

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema_id = len(self._schemas) + 1
        schema = Schema(id=schema_id, data=data, encoding=encoding, name=name)
        self._schemas[schema_id] = schema
        self._add_to_chunk(schema)
        return schema_id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str] | None = None) -> int:
        channel_id = len(self._channels) + 1
        channel = Channel(id=channel_id, topic=topic, message_encoding=message_encoding, schema_id=schema_id,
                          metadata=dict(metadata or {}))
        self._channels[channel_id] = channel
        self._add_to_chunk(channel)
        return channel_id

    def add_message(self, channel_id: int, log_time: int, data: bytes, *, publish_time: int, sequence: int) -> None:
        chunk = self._chunk
        offset = len(chunk)
        chunk += _MESSAGE.pack(Opcode.MESSAGE, _MESSAGE_BODY + len(data), channel_id, sequence, log_time,
                               publish_time)
        chunk += data
        index = self._chunk_index.get(channel_id)
        if index is None:
            self._chunk_index[channel_id] = [log_time, offset]
        else:
            index += (log_time, offset)
        # Times and counts (the chunk's, the statistics') are taken from the index when the chunk
        # closes: the same values, without a dozen attribute updates per message.
        self._chunk_messages += 1
        if len(chunk) > self._chunk_size:
            self._finish_chunk()

    def add_attachment(self, *, create_time: int, log_time: int, name: str, media_type: str, data: bytes) -> None:
        self._flush()
        offset = self._stream.tell()
        self._attachment_count += 1
        attachment = Attachment(create_time=create_time, log_time=log_time, name=name, media_type=media_type,
                                data=data)
        attachment.write(self._records)
        self._attachment_indexes.append(AttachmentIndex(
            offset=offset, length=self._records.count, create_time=create_time, log_time=log_time,
            data_size=len(data), name=name, media_type=media_type))
        self._flush()

    def add_metadata(self, name: str, data: dict[str, str]) -> None:
        self._flush()
        offset = self._stream.tell()
        self._metadata_count += 1
        Metadata(name=name, metadata=data).write(self._records)
        self._metadata_indexes.append(MetadataIndex(offset=offset, length=self._records.count, name=name))
        self._flush()

    # -- internals ------------------------------------------------------------
    def _add_to_chunk(self, record: Schema | Channel) -> None:
        builder = RecordBuilder()
        record.write(builder)
        self._chunk += builder.end()
        if len(self._chunk) > self._chunk_size:
            self._finish_chunk()

    def _flush(self) -> None:
        data = self._records.end()
        if self._data_crcs:
            self._data_crc = zlib.crc32(data, self._data_crc)
        self._stream.write(data)

    def _finish_chunk(self) -> None:
        if self._chunk_messages == 0:
            return
        self._count_chunk_messages()
        self._chunk_count += 1
        chunk_data = bytes(self._chunk)
        compressed = self._compressor.compress(chunk_data) if self._compression == "zstd" else chunk_data
        chunk = Chunk(compression=self._compression, data=compressed, message_start_time=self._chunk_start,
                      message_end_time=self._chunk_end, uncompressed_crc=zlib.crc32(chunk_data),
                      uncompressed_size=len(chunk_data))
        self._flush()
        chunk_start = self._stream.tell()
        chunk.write(self._records)
        chunk_length = self._records.count
        chunk_index = ChunkIndex(
            message_start_time=self._chunk_start, message_end_time=self._chunk_end, chunk_start_offset=chunk_start,
            chunk_length=chunk_length, message_index_offsets={}, message_index_length=0,
            compression=self._compression, compressed_size=len(compressed), uncompressed_size=len(chunk_data))
        self._flush()
        index_start = self._stream.tell()
        parts = []
        at = 0
        for channel_id, flat in self._chunk_index.items():
            chunk_index.message_index_offsets[channel_id] = index_start + at
            body = struct.pack(f"<{len(flat)}Q", *flat)
            parts.append(_INDEX_HEAD.pack(Opcode.MESSAGE_INDEX, 6 + len(body), channel_id, len(body)))
            parts.append(body)
            at += _INDEX_HEAD.size + len(body)
        chunk_index.message_index_length = at
        self._records.write(b"".join(parts))
        self._flush()
        self._chunk_indexes.append(chunk_index)
        self._chunk = bytearray()
        self._chunk_messages = 0
        self._chunk_start = self._chunk_end = 0
        self._chunk_index = {}

    def _count_chunk_messages(self) -> None:
        """The open chunk's first and last log time, and the statistics, from its message index."""
        counts = self._channel_counts
        start = end = None
        for channel_id, flat in self._chunk_index.items():
            times = flat[0::2]
            low, high = min(times), max(times)
            start = low if start is None or low < start else start
            end = high if end is None or high > end else end
            counts[channel_id] = counts.get(channel_id, 0) + len(times)
        assert start is not None and end is not None  # the chunk holds messages
        self._chunk_start, self._chunk_end = start, end
        if self._message_count == 0 or start < self._message_start:
            self._message_start = start
        self._message_end = max(self._message_end, end)
        self._message_count += self._chunk_messages

    def finish(self) -> None:
        """The last chunk, the data end, the summary and the footer (the stream stays open)."""
        self._finish_chunk()
        DataEnd(self._data_crc).write(self._records)
        self._flush()
        summary_start = self._stream.tell()
        summary = RecordBuilder()
        offsets: list[SummaryOffset] = []

        def group(opcode: Opcode, records: Iterable[McapRecord]) -> None:
            start = summary.count
            for record in records:
                record.write(summary)
            offsets.append(SummaryOffset(group_opcode=opcode, group_start=summary_start + start,
                                         group_length=summary.count - start))

        group(Opcode.SCHEMA, self._schemas.values())
        group(Opcode.CHANNEL, self._channels.values())
        group(Opcode.STATISTICS, [Statistics(
            attachment_count=self._attachment_count, channel_count=len(self._channels),
            channel_message_counts=self._channel_counts, chunk_count=self._chunk_count,
            message_count=self._message_count, metadata_count=self._metadata_count,
            message_start_time=self._message_start, message_end_time=self._message_end,
            schema_count=len(self._schemas))])
        group(Opcode.CHUNK_INDEX, self._chunk_indexes)
        group(Opcode.ATTACHMENT_INDEX, self._attachment_indexes)
        group(Opcode.METADATA_INDEX, self._metadata_indexes)
        summary_offset_start = summary_start + summary.count
        for offset in offsets:
            offset.write(summary)
        summary_data = summary.end()
        summary_crc = zlib.crc32(summary_data)
        summary_crc = zlib.crc32(struct.pack("<BQQQ", Opcode.FOOTER, 8 + 8 + 4,
                                             0 if not summary_data else summary_start, summary_offset_start),
                                 summary_crc)
        self._stream.write(summary_data)
        Footer(summary_start=0 if not summary_data else summary_start, summary_offset_start=summary_offset_start,
               summary_crc=summary_crc).write(self._records)
        self._flush()
        self._stream.write(MAGIC)
