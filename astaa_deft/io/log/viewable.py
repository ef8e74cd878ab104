"""A strict-JSON twin for each logged JSON message that carries ``NaN`` or ``±Infinity``.

The bus channel's topic keeps the bytes exactly as delivered (a NaN mutation
must reach the consumer, and the log, as NaN: ``check``, DeFT and minimise read
them). But Foxglove parses JSON messages with a strict parser, which rejects
the bare ``NaN``/``Infinity``/``-Infinity`` tokens, so such a message would be
a hole in the viewer. For each of them the recorder writes a twin on
``/astaa/viewable/<key>`` (same log and publish time, same schema) in strict
JSON, each non-finite number written the way the mutation events already
write it: ``{"float": "nan" | "inf" | "-inf"}``. Every message of the log is
thus viewable, and the exact bytes stay where they were.
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any

from astaa_deft.model.sut import Channel

if TYPE_CHECKING:
    from astaa_deft.io.log.writer import LogWriter

VIEWABLE_PREFIX = "/astaa/viewable/"
_TAGS = {"NaN": "nan", "Infinity": "inf", "-Infinity": "-inf"}


def strict_twin(data: bytes) -> bytes | None:
    """The strict-JSON rendering of ``data`` if it is JSON with non-finite tokens; None otherwise."""
    if b"NaN" not in data and b"Infinity" not in data:  # the common case, checked without parsing
        return None
    found: list[str] = []

    def tag(token: str) -> dict[str, str]:
        found.append(token)
        return {"float": _TAGS[token]}

    def big(text: str) -> Any:  # 1e999: strict JSON, but Python reads it as inf
        number = float(text)
        return number if math.isfinite(number) else {"float": "inf" if number > 0 else "-inf"}

    try:
        value: Any = json.loads(data, parse_constant=tag, parse_float=big)
    except (ValueError, RecursionError):  # not JSON at all: flagged elsewhere, nothing to render
        return None
    if not found:  # the letters were inside strings
        return None
    try:
        return json.dumps(value, allow_nan=False, ensure_ascii=True, separators=(",", ":")).encode("ascii")
    except (ValueError, RecursionError):
        return None


class ViewableTwins:
    """Writes the twins through a LogWriter, one MCAP channel per bus channel, registered on first use."""

    def __init__(self, writer: LogWriter, channels: dict[str, Channel]) -> None:
        self._writer = writer
        self._channels = channels  # by channel name
        self._ids: dict[str, int] = {}

    def add(self, name: str, log_time: int, data: bytes, publish_time: int) -> None:
        twin = strict_twin(data)
        if twin is None:
            return
        if name not in self._ids:
            channel = self._channels[name]
            self._ids[name] = self._writer.bus_channel(channel, topic=VIEWABLE_PREFIX + channel.key)
        self._writer.message(self._ids[name], log_time, twin, publish_time)
