"""Evaluation only: which inputs a member's output used, as the module itself recorded it (``debug.inputs``).

No extraction may read this unless a spec declares it as provenance; the
benchmark and tests use it to tell whether a frame chosen is the right one.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any


def frame_truth(output: Mapping[str, Any] | bytes) -> dict[str, int | None]:
    """{input channel: header.seq of the message the cycle used, None: absent} of one output (decoded or JSON)."""
    message = json.loads(output) if isinstance(output, (bytes, bytearray, memoryview)) else output
    return dict(message["debug"]["inputs"])


def chosen_seqs(inputs: Mapping[str, Any]) -> dict[str, int | None]:
    """{channel: header.seq} of a frame's inputs (decoded messages or logged ones with JSON ``data``)."""
    out: dict[str, int | None] = {}
    for name, message in inputs.items():
        body = json.loads(message.data) if hasattr(message, "data") else message
        out[name] = int(body["header"]["seq"])
    return out


def right_frame(output: Mapping[str, Any] | bytes, inputs: Mapping[str, Any]) -> bool:
    """The frame ``inputs`` is the one the module used for ``output`` (absent inputs absent too)."""
    truth = frame_truth(output)
    chosen = chosen_seqs(inputs)
    return all(chosen.get(name) == seq for name, seq in truth.items())
