"""The attachment rmw_zenoh puts on every ROS 2 message: sequence number, source timestamp, GID.

33 bytes, little endian: int64 sequence number, int64 source timestamp (ns
since the Unix epoch), then the publisher's GID as a length-prefixed byte
string (length byte 16, 16 bytes). zenoh-ros2-sdk writes the same layout
(unsigned, any GID length up to 255), so any length byte is read.

The proxy forwards attachments untouched; the tool only reads them: the
source timestamp becomes a recorded message's ``publish_time`` and the
sequence number and GID tell publishers and gaps apart in reports.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

_HEAD = struct.Struct("<qqB")


@dataclass(frozen=True)
class RmwAttachment:
    sequence: int
    source_time_ns: int
    gid: bytes

    def to_bytes(self) -> bytes:
        return _HEAD.pack(self.sequence, self.source_time_ns, len(self.gid)) + self.gid


def parse_attachment(data: bytes | None) -> RmwAttachment | None:
    """The attachment's fields, or None if ``data`` is not an rmw_zenoh attachment."""
    if data is None or len(data) < _HEAD.size:
        return None
    sequence, source_time_ns, gid_length = _HEAD.unpack_from(data)
    if len(data) != _HEAD.size + gid_length:
        return None
    return RmwAttachment(sequence, source_time_ns, bytes(data[_HEAD.size:]))
