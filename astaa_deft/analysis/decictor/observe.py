"""A run's observation for Decictor's oracle, read from its log: ego path, goal, collision, lanes.

The ego's states come from the channel the spec's ``decictor.ego`` names (at
its own times, ``header.stamp`` by default: the SUT's clock, the one the
participants' paths use); the goal and collision flags from the last message
of their channel; straight lanes from the first message of the lanes
channel. A damaged or unfinished log is never read as a clean run
(``ObservationError``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from astaa_deft.io.codecs import DecodeError, get_codec
from astaa_deft.model.fields import FieldPath, get
from astaa_deft.io.log.reader import LogContents, read_log
from astaa_deft.model.sut import Spec
from astaa_deft.analysis.decictor.config import DecictorConfig, lanes_from_message, read_lanes_file
from astaa_deft.analysis.decictor.oracle import Lane, RunObservation
from astaa_deft.analysis.decictor.paths import EgoPath, EgoState
from astaa_deft.model.errors import AstaaDeftError


class ObservationError(AstaaDeftError, ValueError):
    """The run cannot be judged from its log."""

    exit_code = 2  # bad input: the CLI prints it as one line


@dataclass(frozen=True)
class LoggedRun:
    observation: RunObservation
    lanes: tuple[Lane, ...]


def observe_log(path: Path, spec: Spec, config: DecictorConfig) -> LoggedRun:
    log = read_log(path)
    if not log.intact:
        raise ObservationError(f"{path}: the log is damaged or unfinished: {log.describe_reading()}")
    return observe(log, spec, config)


def _messages(log: LogContents, spec: Spec, channel: str) -> list[dict]:
    codec = get_codec(spec.channel(channel).encoding)
    out = []
    for message in sorted(log.on(spec.channel(channel).key), key=lambda m: m.log_time):
        try:
            out.append(codec.decode(message.data))
        except DecodeError:
            continue
    return out


def _value(message: dict, path: str) -> object:
    found = get(message, FieldPath.parse(path))
    return found[0][1] if found else None


def _number(message: dict, path: str) -> float | None:
    value = _value(message, path)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return None
    return float(value)


def observe(log: LogContents, spec: Spec, config: DecictorConfig) -> LoggedRun:
    ego = config.ego
    states: list[EgoState] = []
    for message in _messages(log, spec, ego.channel):
        t, x, y, heading = (_number(message, p) for p in (ego.t, ego.x, ego.y, ego.heading))
        if t is None or x is None or y is None or heading is None:
            continue
        if states and t <= states[-1].t:  # held world (t = 0 repeated) and repeats: keep time increasing
            continue
        states.append(EgoState(t=t, x=x, y=y, heading=heading, speed=_number(message, ego.speed) or 0.0,
                               acceleration=_number(message, ego.acceleration) or 0.0))
    if not states:
        raise ObservationError(f"{log.path}: no usable message on the ego channel '{ego.channel}'")
    flags = {}
    for name, flag in (("goal", config.goal), ("collision", config.collision)):
        if flag is None:
            flags[name] = False
            continue
        messages = _messages(log, spec, flag.channel)
        flags[name] = bool(messages) and _value(messages[-1], flag.field) is True
    if config.lanes.file is not None:
        lanes = read_lanes_file(config.lanes.file)
    else:
        lane_messages = _messages(log, spec, config.lanes.channel)  # type: ignore[arg-type]
        if not lane_messages:
            raise ObservationError(f"{log.path}: no message on the lanes channel '{config.lanes.channel}'")
        try:
            lanes = lanes_from_message(config.lanes, lane_messages[0])
        except ValueError as exc:
            raise ObservationError(str(exc)) from None
    path = EgoPath(tuple(states), ego.length, ego.width)
    return LoggedRun(RunObservation(path, flags["goal"], flags["collision"]), lanes)
