"""Message codecs by name: a channel's ``encoding`` in the spec picks one.

Codec names are also MCAP well-known message encodings ("json", "cbor"), so
a recorder can use ``codec.name`` as the channel's ``message_encoding``.
A family of codecs is named ``family:argument``: ``cdr:geometry_msgs/msg/Twist``
is the ROS 2 CDR codec of that type (``message_encoding`` "cdr"), built on
first use.
"""

from __future__ import annotations

from astaa_deft.model.errors import AstaaDeftError
from astaa_deft.io.codecs.base import Codec, CodecError, DecodeError, EncodeError, same_value
from astaa_deft.io.codecs.cbor_codec import CborCodec
from astaa_deft.io.codecs.json_codec import JsonCodec

__all__ = [
    "Codec", "CodecError", "DecodeError", "EncodeError", "UnknownCodecError",
    "available_codecs", "get_codec", "register_codec", "same_value",
]


class UnknownCodecError(AstaaDeftError, KeyError):
    """No codec has that name; the message lists the known ones."""

    def __str__(self) -> str:  # KeyError would show the message in quotes
        return str(self.args[0])


_REGISTRY: dict[str, Codec] = {}


def register_codec(codec: Codec, *, replace: bool = False) -> None:
    """Make ``codec`` available under ``codec.name``; refuses to shadow one unless ``replace``."""
    if codec.name in _REGISTRY and not replace:
        raise ValueError(f"a codec named {codec.name!r} is already registered")
    _REGISTRY[codec.name] = codec


def get_codec(name: str) -> Codec:
    """The codec called ``name`` (codecs are stateless and shared)."""
    try:
        return _REGISTRY[name]
    except KeyError:
        pass
    family, _, argument = name.partition(":")
    if argument and family == "cdr":
        from astaa_deft.io.codecs.cdr import codec_for_type  # rosbags loads only for ROS 2 systems

        try:
            codec: Codec = codec_for_type(argument)
        except ValueError as exc:  # Ros2TypeError: an unknown type, with close names
            raise UnknownCodecError(f"unknown encoding {name!r}: {exc}") from None
        _REGISTRY.setdefault(name, codec)
        return _REGISTRY[name]
    known = ", ".join(n for n in available_codecs() if ":" not in n)
    raise UnknownCodecError(f"unknown encoding {name!r}; known encodings: {known}, cdr:<ROS 2 type>") from None


def available_codecs() -> tuple[str, ...]:
    return tuple(sorted(_REGISTRY))


register_codec(JsonCodec())
register_codec(CborCodec())
