"""Hand-made runs for the monitor tests: a small driving-stack spec and real MCAP logs.

Times in these helpers are seconds after ``T0`` (converted to ns), so a test
reads like its scenario: "a NaN at 1.3 s is reported at 1.3 s".
"""

from __future__ import annotations

import json
import textwrap
from pathlib import Path
from typing import Any

import pytest

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.log.reader import LogContents, read_log
from astaa_deft.io.log.writer import LogWriter
from astaa_deft.engine.monitor import with_typed_invariants
from astaa_deft.engine.spec.loader import load_spec_text
from astaa_deft.model.sut import Spec

T0 = 1_700_000_000_000_000_000  # ns: the run's start in every hand-made log

BASE_SPEC = (Path(__file__).parent / "data" / "driving_stack.yaml").read_text()


def spec_text(invariants: str) -> str:
    """The base spec with ``invariants`` (YAML list items, unindented) as its invariants section."""
    return BASE_SPEC + "invariants:\n" + textwrap.indent(textwrap.dedent(invariants).strip("\n"), "  ") + "\n"


def load(invariants: str) -> Spec:
    return with_typed_invariants(load_spec_text(spec_text(invariants), name="sut.yaml"), source_name="sut.yaml")


def spec_problems(invariants: str) -> list[Problem]:
    """The problems a spec with these invariants is refused for (fails the test if it loads)."""
    with pytest.raises(InputError) as caught:
        load(invariants)
    return caught.value.problems


def line_of(text: str, needle: str) -> int:
    """1-based number of the first line of the invariants section holding ``needle``."""
    lines = text.splitlines()
    start = lines.index("invariants:")
    for number, line in enumerate(lines[start:], start=start + 1):
        if needle in line:
            return number
    raise AssertionError(f"{needle!r} not in the invariants")


def ns(seconds: float) -> int:
    return T0 + round(seconds * 1e9)


class HandMadeLog:
    """Write a real MCAP log message by message, the way the recorder does."""

    def __init__(self, path: Path, spec: Spec, started: bool = True):
        self.path = path
        self.spec = spec
        self.writer = LogWriter(path, spec)
        self.seq: dict[str, int] = {}
        if started:
            self.event("run_started", 0.0, mode="star", spec=spec.name)

    def message(self, channel: str, at: float, value: Any, published: float | None = None) -> int:
        """Log ``value`` on ``channel`` at ``at`` seconds; returns its seq (1-based, per channel).

        ``published``: the message's own (Zenoh) time, when it differs from when the recorder got it.
        """
        declared = self.spec.channel(channel)
        cid = self.writer.bus_channel(declared)
        if isinstance(value, (bytes, bytearray)):
            data = bytes(value)
        elif declared.encoding == "cbor":
            import cbor2
            data = cbor2.dumps(value)
        else:
            data = json.dumps(value).encode()
        return self.writer.message(cid, ns(at), data, ns(published) if published is not None else None)

    def event(self, kind: str, at: float, **fields: Any) -> None:
        self.writer.event(kind, time_ns=ns(at), **fields)

    def exit(self, module: str, at: float, returncode: int = 0, signal: str | None = None,
             during_shutdown: bool = False) -> None:
        self.event("process_exit", at, module=module, pid=1234, returncode=returncode, signal=signal,
                   during_shutdown=during_shutdown, abnormal=not during_shutdown and (returncode != 0 or bool(signal)),
                   stderr_tail="Traceback ...\nValueError: boom\n" if returncode else "")

    def close(self) -> LogContents:
        self.writer.finish()
        return read_log(self.path)


def pose(seq: int, x: float, speed: float = 10.0, y: float = 0.0, heading: float = 0.0) -> dict:
    return {"header": {"seq": seq, "stamp": seq * 0.1}, "x": x, "y": y, "heading": heading, "speed": speed}


def obstacles(seq: int, *items: dict) -> dict:
    return {"header": {"seq": seq, "stamp": seq * 0.1}, "obstacles": list(items)}


def obstacle(id_: int, x: float, y: float = 0.0, heading: float = 0.0, length: float = 4.0,
             width: float = 2.0) -> dict:
    return {"id": id_, "x": x, "y": y, "heading": heading, "length": length, "width": width}


def trajectory(seq: int, speeds=(5.0, 5.0, 5.0), gear: str = "drive") -> dict:
    return {"header": {"seq": seq, "stamp": seq * 0.1},
            "points": [{"t": i * 0.1, "x": i * 0.5, "v": v} for i, v in enumerate(speeds)], "gear": gear}


def command(seq: int, acceleration: float = 0.5) -> dict:
    return {"header": {"seq": seq, "stamp": seq * 0.1}, "acceleration": acceleration, "steering": 0.0}


def lights(seq: int, state: str, stop_line_x: float = 100.0) -> dict:
    return {"header": {"seq": seq, "stamp": seq * 0.1}, "lights": [{"id": 1, "state": state,
                                                                     "stop_line_x": stop_line_x}]}
