"""Frames on the pipes and sockets between the tool's own processes, and the typed messages they carry.

One framing for every channel between a process of the tool and a child it
started (case workers, the case template, replay workers, forked replay
copies). A frame is an 8-byte header — the magic ``b"\\xadF"``, one byte
naming the body's encoding, one zero byte, the body's length (unsigned
32-bit, big-endian) — and the body. A reader refuses a header that is not
one (garbled) or announces more than its bound (``max_bytes``) before
reading the body, so a damaged stream costs neither a hang nor unbounded
memory; a stream that ends inside a frame (the sender died mid-frame) is a
:class:`FrameError`, never a short message, and a stream that ends between
frames is the clean end (``None``).

Messages are frozen dataclasses with ``TAG``, ``to_json()`` and
``from_json()`` (:class:`PipeMessage`); a frame carries one as JSON of
``{"type": TAG, **to_json()}`` (JSON rather than CBOR, though both are
read: measured on the replay pool's round trip, docs/performance.md
"pipes"; and readable when a channel is traced). The receiver names
the message types it accepts; anything else is a :class:`FrameError`.
:func:`encode_pickle`/:func:`decode_pickle` put a pickle in a frame for the
one channel that carries the planner's own objects between forked copies of
one process (analysis/deft/fork_replay.py), where no other process reads it.

Thread safety: the functions keep no state; a channel must be written by one
thread at a time and read by one thread at a time (a frame is written with
several calls).
"""

from __future__ import annotations

import json
import os
import pickle
import socket
import struct
from collections.abc import Callable, Iterable, Mapping
from typing import TYPE_CHECKING, ClassVar, Protocol, TypeVar

import cbor2

from astaa_deft.model.errors import AstaaDeftError
from astaa_deft.model.json import JsonObject

if TYPE_CHECKING:  # Python 3.10 has no typing.Self
    from typing_extensions import Self

MAGIC = b"\xadF"
_HEADER = struct.Struct(">2sBxI")
HEADER_BYTES = _HEADER.size
MESSAGE_LIMIT = 64 << 20  # bytes: the largest message frame a reader accepts by default (a case's outcome, a job)
BULK_LIMIT = (1 << 32) - 1  # bytes: the largest frame there is (a forked replay's whole extraction)


class BodyEncoding(int):
    """The body's encoding byte in a frame header."""


CBOR = BodyEncoding(ord("C"))
JSON = BodyEncoding(ord("J"))
PICKLE = BodyEncoding(ord("P"))
_ENCODINGS = frozenset({CBOR, JSON, PICKLE})
MESSAGE_ENCODING = JSON  # what messages are written as (measured: docs/performance.md "pipes"); both are read

Reader = Callable[[int], bytes]
"""Up to n bytes from a channel; ``b""`` at its end (``os.read`` on an fd, ``socket.recv``, a binary file's read)."""


class FrameError(AstaaDeftError):
    """A frame that is not one: garbled, too large, cut short by the end of the stream, or an unexpected message.

    The message names the channel (``source``) and what was wrong.
    """


class PipeMessage(Protocol):
    """A message on a channel: a frozen dataclass with a ``TAG`` unique among its channel's messages."""

    TAG: ClassVar[str]

    def to_json(self) -> JsonObject: ...

    @classmethod
    def from_json(cls, data: JsonObject) -> Self: ...


M = TypeVar("M", bound=PipeMessage)
F = TypeVar("F", bound="FieldlessMessage")


class FieldlessMessage:
    """Base of a message that has no fields (a request, a stop): subclasses set ``TAG``."""

    TAG: ClassVar[str]

    def to_json(self) -> JsonObject:
        return {}

    @classmethod
    def from_json(cls: type[F], data: JsonObject) -> F:
        return cls()


# -- frames ------------------------------------------------------------------------------------------


def frame(body: bytes, encoding: BodyEncoding = CBOR) -> bytes:
    """``body`` with its header; raises :class:`FrameError` when it is longer than any frame may be."""
    if len(body) > BULK_LIMIT:
        raise FrameError(f"a frame of {len(body)} bytes is over the limit of {BULK_LIMIT}")
    return _HEADER.pack(MAGIC, encoding, len(body)) + body


def write_fd(fd: int, data: bytes) -> None:
    """All of ``data`` written to ``fd`` (``os.write`` may take a part); raises the ``OSError`` of a closed pipe."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _read_exactly(read: Reader, size: int) -> tuple[bytes, int]:
    """(the bytes read, how many): all ``size`` unless the channel ended first."""
    chunks, got = [], 0
    while got < size:
        chunk = read(min(size - got, 1 << 20))
        if not chunk:
            break
        chunks.append(chunk)
        got += len(chunk)
    return b"".join(chunks), got


def read_frame(read: Reader, *, source: str, max_bytes: int = MESSAGE_LIMIT) -> tuple[BodyEncoding, bytes] | None:
    """The next frame's (encoding, body) from ``read``; None when the channel ended between frames.

    Raises :class:`FrameError` naming ``source`` for a garbled header, a body
    over ``max_bytes`` (checked before it is read), or a channel that ended
    inside the frame; the ``OSError`` of ``read`` (a socket's timeout) as it is.
    """
    head, got = _read_exactly(read, HEADER_BYTES)
    if got == 0:
        return None
    if got < HEADER_BYTES:
        raise FrameError(f"{source}: the channel ended inside a frame's header ({got} of {HEADER_BYTES} bytes; "
                         "the sender died mid-frame?)")
    magic, encoding, size = _HEADER.unpack(head)
    if magic != MAGIC or encoding not in _ENCODINGS:
        raise FrameError(f"{source}: garbled frame header {head.hex()} (not written by this tool's framing)")
    if size > max_bytes:
        raise FrameError(f"{source}: a frame of {size} bytes is over this channel's limit of {max_bytes}")
    body, got = _read_exactly(read, size)
    if got < size:
        raise FrameError(f"{source}: the channel ended inside a frame ({got} of {size} bytes; "
                         "the sender died mid-frame?)")
    return BodyEncoding(encoding), body


def fd_reader(fd: int) -> Reader:
    """A :data:`Reader` on a file descriptor."""
    return lambda size: os.read(fd, size)


def bytes_reader(data: bytes) -> Reader:
    """A :data:`Reader` on bytes already read (a child's whole output)."""
    view, position = memoryview(data), 0

    def read(size: int) -> bytes:
        nonlocal position
        chunk = bytes(view[position:position + size])
        position += len(chunk)
        return chunk

    return read


# -- typed messages ----------------------------------------------------------------------------------


def encode(message: PipeMessage, encoding: BodyEncoding = MESSAGE_ENCODING) -> bytes:
    """``message`` as one frame, its body in ``encoding`` (CBOR or JSON)."""
    data = {"type": message.TAG, **message.to_json()}
    if encoding == JSON:
        return frame(json.dumps(data, separators=(",", ":")).encode(), JSON)
    return frame(cbor2.dumps(data), CBOR)


def decode(encoding: BodyEncoding, body: bytes, kinds: Iterable[type[M]], *, source: str) -> M:
    """The message a frame's body holds, of one of ``kinds``; :class:`FrameError` naming ``source`` otherwise."""
    if encoding not in (CBOR, JSON):
        raise FrameError(f"{source}: a frame of encoding {encoding!r} where a message was expected")
    try:
        data = cbor2.loads(body) if encoding == CBOR else json.loads(body)
    except (cbor2.CBORDecodeError, ValueError, TypeError) as exc:
        raise FrameError(f"{source}: a garbled message ({exc})") from None
    by_tag: Mapping[str, type[M]] = {kind.TAG: kind for kind in kinds}
    tag = data["type"] if isinstance(data, dict) and "type" in data else None
    if not isinstance(tag, str) or tag not in by_tag:
        found = tag if isinstance(data, dict) else type(data).__name__
        raise FrameError(f"{source}: an unexpected message {found!r} (expected one of {', '.join(by_tag)})")
    fields = {key: value for key, value in data.items() if key != "type"}
    try:
        return by_tag[tag].from_json(fields)
    except (KeyError, TypeError, ValueError) as exc:
        raise FrameError(f"{source}: a malformed {tag!r} message ({type(exc).__name__}: {exc})") from None


def receive(read: Reader, kinds: Iterable[type[M]], *, source: str, max_bytes: int = MESSAGE_LIMIT) -> M | None:
    """The next message from ``read`` (:func:`read_frame`, :func:`decode`); None at the channel's clean end."""
    got = read_frame(read, source=source, max_bytes=max_bytes)
    if got is None:
        return None
    return decode(*got, kinds, source=source)


def send_fd(fd: int, message: PipeMessage) -> None:
    """``message`` as one frame on a pipe's fd."""
    write_fd(fd, encode(message))


def send_socket(sock: socket.socket, message: PipeMessage) -> None:
    """``message`` as one frame on a socket."""
    sock.sendall(encode(message))


# -- the planner's own objects between forked copies of one process --------------------------------------


def encode_pickle(obj: object) -> bytes:
    """``obj`` pickled, as one frame (only for a channel between forked copies of one process)."""
    return frame(pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL), PICKLE)


def decode_pickle(encoding: BodyEncoding, body: bytes, *, source: str) -> object:
    """The object a pickle frame holds; :class:`FrameError` naming ``source`` for any other frame or a bad pickle."""
    if encoding != PICKLE:
        raise FrameError(f"{source}: a frame of encoding {encoding!r} where a pickle was expected")
    try:
        return pickle.loads(body)
    except (pickle.UnpicklingError, EOFError, AttributeError, ImportError, ValueError) as exc:
        raise FrameError(f"{source}: a garbled pickle ({type(exc).__name__}: {exc})") from None
