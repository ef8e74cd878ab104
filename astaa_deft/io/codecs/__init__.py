"""Message codecs by name: a channel's ``encoding`` in the spec picks one.

Codec names are also MCAP well-known message encodings ("json", "cbor"), so
a recorder can use ``codec.name`` as the channel's ``message_encoding``.
A family of codecs is named ``family:argument``: ``cdr:geometry_msgs/msg/Twist``
is the ROS 2 CDR codec of that type (``message_encoding`` "cdr"), built on
first use.

Both are registries (``model.registry.Registry``): a codec's module registers
one instance on ``CODECS`` (``json_codec.py``, ``cbor_codec.py``), a family's
module a builder on ``CODEC_FAMILIES`` (``cdr_family.py``). Adding a codec is
adding such a module here; the spec reader's encodings are these names.
"""

from __future__ import annotations

from astaa_deft.model.errors import AstaaDeftError
from astaa_deft.io.codecs.base import (
    CODEC_FAMILIES, CODECS, Codec, CodecError, DecodeError, EncodeError, same_value,
)

__all__ = [
    "CODECS", "CODEC_FAMILIES", "Codec", "CodecError", "DecodeError", "EncodeError", "UnknownCodecError",
    "available_codecs", "encoding_names", "get_codec", "register_codec", "same_value",
]


class UnknownCodecError(AstaaDeftError, KeyError):
    """No codec has that name; the message lists the known ones."""

    def __str__(self) -> str:  # KeyError would show the message in quotes
        return str(self.args[0])


_BUILT: dict[str, Codec] = {}  # codecs of a family, by their full name (built on first use)


def register_codec(codec: Codec, *, replace: bool = False) -> None:
    """Make ``codec`` available under ``codec.name``; refuses to shadow one unless ``replace``."""
    if codec.name in CODECS:
        if not replace:
            raise ValueError(f"a codec named {codec.name!r} is already registered")
        CODECS.unregister(codec.name)
    CODECS.register(codec.name, codec)


def get_codec(name: str) -> Codec:
    """The codec called ``name`` (codecs are stateless and shared)."""
    codec = CODECS.get(name) or _BUILT.get(name)
    if codec is not None:
        return codec
    family, _, argument = name.partition(":")
    build = CODEC_FAMILIES.get(family) if argument else None
    if build is not None:
        try:
            built = build(argument)
        except ValueError as exc:  # Ros2TypeError: an unknown type, with close names
            raise UnknownCodecError(f"unknown encoding {name!r}: {exc}") from None
        return _BUILT.setdefault(name, built)
    families = ", ".join(f"{f}:<argument>" for f in CODEC_FAMILIES.names())
    raise UnknownCodecError(f"unknown encoding {name!r}; known encodings: {', '.join(available_codecs())}"
                            + (f", {families}" if families else "")) from None


def available_codecs() -> tuple[str, ...]:
    """The registered codecs' names (a family's built codecs are not listed)."""
    return CODECS.names()


def encoding_names() -> tuple[str, ...]:
    """What a spec's ``encoding:`` may say: every codec's name, then every family's."""
    return CODECS.names() + CODEC_FAMILIES.names()
