"""Write a self-contained MCAP test log (through ``mcap_writer``: the bytes of ``mcap``'s writer, faster).

Chunks are small (64 KiB by default) so that a recorder killed mid-run loses
at most one chunk: the streaming reader recovers every complete chunk.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import BinaryIO
from collections.abc import Mapping

from astaa_deft import __version__
from astaa_deft.io.codecs.jsonschema import json_schema
from astaa_deft.model.sut import Channel, Spec
from astaa_deft.io.ros2.types import shared_types
from astaa_deft.io.log import layout
from astaa_deft.io.log import records
from astaa_deft.io.log.mcap_writer import McapWriter
from astaa_deft.io.output_place import open_new

DEFAULT_CHUNK_SIZE = 64 * 1024


class LogWriter:
    def __init__(self, path: Path, spec: Spec | None, chunk_size: int = DEFAULT_CHUNK_SIZE,
                 compression: str = "zstd"):
        self.path = Path(path)
        # a new file, never through a link (io/output_place.py); lives as long as the writer (finish)
        self._stream: BinaryIO = open_new(self.path)
        self._writer = McapWriter(
            self._stream,
            chunk_size=chunk_size,
            compression="zstd" if compression == "zstd" else "",
            enable_data_crcs=True,  # the data section's CRC: damage outside chunks (headers, indexes) is detectable
        )
        self._writer.start(profile=layout.PROFILE, library=f"astaa-deft {__version__}")
        self._spec = spec
        self._schemas: dict[str, int] = {}
        self._topics: dict[str, int] = {}
        self._sequences: dict[int, int] = {}
        self._finished = False
        self.events_channel = self.tool_channel(layout.EVENTS_TOPIC)
        self.flags_channel = self.tool_channel(layout.FLAGS_TOPIC)

    # -- channels ----------------------------------------------------------
    def bus_channel(self, channel: Channel, topic: str | None = None) -> int:
        """The MCAP channel for a declared bus channel (topic = its key)."""
        topic = topic or channel.key
        if topic in self._topics:
            return self._topics[topic]
        schema_id = 0
        message_encoding = channel.encoding
        if channel.encoding == "json" and self._spec is not None and channel.type in self._spec.types:
            schema_id = self._schema(channel.type, json_schema(self._spec.types, channel.type))
        elif channel.encoding.startswith("cdr:"):  # ROS 2: as `ros2 bag record -s mcap` writes it
            schema_id = self._ros2_schema(channel.type)
            message_encoding = "cdr"
        cid = self._writer.register_channel(
            topic=topic,
            message_encoding=message_encoding,
            schema_id=schema_id,
            metadata={
                "channel": channel.name,
                "key": channel.key,
                "producer": channel.producer,
                "consumers": ",".join(channel.consumers),
                "type": channel.type,
                **({"ros2_topic": channel.topic} if channel.topic else {}),
            },
        )
        self._topics[topic] = cid
        return cid

    def undeclared_channel(self, key: str, encoding: str = "") -> int:
        if key in self._topics:
            return self._topics[key]
        cid = self._writer.register_channel(topic=key, message_encoding=encoding or "unknown", schema_id=0,
                                            metadata={"undeclared": "true"})
        self._topics[key] = cid
        return cid

    def tool_channel(self, topic: str) -> int:
        schema_id = self._schema("astaa_deft.Event", layout.EVENT_SCHEMA)
        cid = self._writer.register_channel(topic=topic, message_encoding="json", schema_id=schema_id)
        self._topics[topic] = cid
        return cid

    def _schema(self, name: str, schema: Mapping[str, object]) -> int:
        if name not in self._schemas:
            self._schemas[name] = self._writer.register_schema(
                name=name, encoding="jsonschema", data=json.dumps(schema).encode()
            )
        return self._schemas[name]

    def _ros2_schema(self, type_name: str) -> int:
        if type_name not in self._schemas:
            self._schemas[type_name] = self._writer.register_schema(
                name=type_name, encoding="ros2msg", data=shared_types().msgdef(type_name).encode())
        return self._schemas[type_name]

    # -- records -----------------------------------------------------------
    def message(self, channel_id: int, log_time_ns: int, data: bytes, publish_time_ns: int | None = None) -> int:
        seq = self._sequences.get(channel_id, 0) + 1
        self._sequences[channel_id] = seq
        self._writer.add_message(channel_id, log_time_ns, data,
                                 publish_time=publish_time_ns if publish_time_ns is not None else log_time_ns,
                                 sequence=seq)
        return seq

    def event(self, kind: str, time_ns: int | None = None, channel_id: int | None = None, **fields: object) -> None:
        """A raw event body, as given: for crafting logs (tests, benchmarks); the tool itself writes records."""
        t = time_ns if time_ns is not None else time.time_ns()
        body = {"kind": kind, "time_ns": t, **fields}
        self.message(self.events_channel if channel_id is None else channel_id, t,
                     json.dumps(body, default=str).encode())

    def record(self, record: records.Record, channel_id: int | None = None) -> None:
        """One typed event record (the events topic unless ``channel_id`` says otherwise)."""
        self.message(self.events_channel if channel_id is None else channel_id, record.time_ns,
                     records.to_json_text(record).encode())

    def attachment(self, name: str, data: bytes, media_type: str = "application/octet-stream") -> None:
        now = time.time_ns()
        self._writer.add_attachment(create_time=now, log_time=now, name=name, media_type=media_type, data=data)

    def metadata(self, name: str, data: Mapping[str, str]) -> None:
        self._writer.add_metadata(name, {k: str(v) for k, v in data.items()})

    def finish(self) -> None:
        if self._finished:
            return
        self._finished = True
        self._writer.finish()
        self._stream.close()
