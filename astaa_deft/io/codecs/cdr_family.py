"""The ``cdr`` family: ``cdr:<ROS 2 type>`` is the CDR codec of that message type (``cdr``).

Its own module so that the family is known (the spec reader's encodings list
it) without loading rosbags: ``cdr`` is imported when the first such codec
is built, for ROS 2 systems only.
"""

from __future__ import annotations

from astaa_deft.io.codecs.base import CODEC_FAMILIES, Codec


def cdr_codec(type_name: str) -> Codec:
    """The CDR codec of ``type_name``; ValueError (Ros2TypeError) naming close types for an unknown one."""
    from astaa_deft.io.codecs.cdr import codec_for_type  # rosbags loads only for ROS 2 systems

    return codec_for_type(type_name)


CODEC_FAMILIES.register("cdr", cdr_codec)
