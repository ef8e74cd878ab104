"""A replayed output judged against the recorded one, decoded once per output.

Trajectories (the planner) are compared point by point, any other module's
output field by field; an output equal to the recording, text for text, is
known to match without measuring (docs/performance.md, "analysis").
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import cast

from astaa_deft.analysis.deft.replay import compare_outputs, trajectory_points
from astaa_deft.analysis.deft.validator import Comparison, Point, compare, identical
from astaa_deft.engine.spec.replay_section import ReplayModule
from astaa_deft.model.json import DecodedMessage


@dataclass(frozen=True)
class Expected:
    """A recorded output as every candidate's replayed output is judged against it (computed once per output)."""

    message: object  # decoded; None if it does not decode
    points: list[Point]  # its trajectory's points (a planner with a trajectory layout), else []
    text: str  # its text form (see text_of)


@dataclass(frozen=True)
class Judged:
    """The kept candidate's judgement: its comparison, whether it reproduced the output field for field,
    the candidates tried for it (all of them when none was within θ)."""

    comparison: Comparison
    exact: bool
    tries: int


def compare_replayed(cfg: ReplayModule, replayed: object, expected: object, expected_points: Sequence[Point]
                     ) -> Comparison:
    """The planner's trajectories (points decoded once per output), or any module's output field by field."""
    if cfg.trajectory is not None:
        return compare(trajectory_points(replayed, cfg.trajectory), expected_points)
    return compare_outputs(cfg, replayed, expected)


def judged(cfg: ReplayModule, replayed: object, expected: Expected) -> tuple[Comparison, bool]:
    """(comparison, equal to the recorded output field for field) of one replayed output.

    Most replayed outputs equal the recording: then the trajectories are
    the same points, and their comparison is known without measuring
    (``validator.identical``; why: docs/performance.md, "analysis").
    """
    exact = text_of(replayed) == expected.text
    if exact and cfg.trajectory is not None:
        return identical(expected.points), True
    return compare_replayed(cfg, replayed, expected.message, expected.points), exact


NEAR_MISS_M = 1e-9


def decoded(frame: Mapping[str, DecodedMessage | None]) -> dict[str, DecodedMessage] | None:
    """``frame`` when every input in it decodes (the module's input), else None."""
    if any(v is None for v in frame.values()):
        return None
    return cast(dict[str, DecodedMessage], dict(frame))


def as_logged(frame: Mapping[str, DecodedMessage | None]) -> Mapping[str, DecodedMessage]:
    """``frame`` stepped as it is, an input that does not decode handed over as None (the plain walk steps every
    trigger as logged, and a copy of the state is measured on the frame kept)."""
    return cast(Mapping[str, DecodedMessage], frame)


def text_of(value: object) -> str:
    """A decoded message as text that is equal exactly when the messages are equal field for field."""
    return json.dumps(value, sort_keys=True, default=str)


def same_fields(a: object, b: object) -> bool:
    return text_of(a) == text_of(b)
