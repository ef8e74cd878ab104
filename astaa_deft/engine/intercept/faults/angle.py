"""``angle``: an angle a turn or half a turn off (± 2π, ± π) or never wrapped back (two turns on): the
same direction to a human, another number to code that forgot to normalise.

Angles are float fields named like one (heading, yaw, theta, …; not a rate),
or declared with the range of one: [-π, π], [0, 2π] or [-2π, 2π]."""

from __future__ import annotations

import math
import re

from astaa_deft.model.fields import FieldPath
from astaa_deft.model.sut import FLOAT_KINDS, Channel, FieldType
from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import ValueFamily

# Two turns on first: code that breaks on one turn off (no normalisation at all) breaks on it too, and so
# does code that wraps only once.
_KEYS = ("float.unwrapped", "float.plus_pi", "float.plus_2pi", "float.minus_2pi", "float.minus_pi")
# A name part that says "angle": heading, yaw_rate is not one (a rate), steering_angle is.
ANGLE_NAME = re.compile(r"(heading|yaw|theta|angle|bearing|orientation|azimuth|course|phi|psi|roll|pitch)",
                        re.IGNORECASE)
RATE_NAME = re.compile(r"(rate|speed|velocity|dot|accel)", re.IGNORECASE)


def looks_like_angle(path: FieldPath, field_type: FieldType) -> bool:
    name = next((s for s in reversed(path.segments) if type(s) is str), "")
    if ANGLE_NAME.search(name) and not RATE_NAME.search(name):
        return True
    low, high = field_type.minimum, field_type.maximum
    if low is None or high is None:
        return False
    return any(math.isclose(low, a, abs_tol=1e-3) and math.isclose(high, b, abs_tol=1e-3) for a, b in ANGLE_RANGES)


ANGLE_RANGES = ((-math.pi, math.pi), (0.0, 2 * math.pi), (-2 * math.pi, 2 * math.pi))


class Angle(ValueFamily):
    name = "angle"
    weight = 4
    rank = 7
    owns = _KEYS
    keys_of_kind = {kind: _KEYS for kind in FLOAT_KINDS}

    def accepts(self, channel: Channel, path: FieldPath, field_type: FieldType) -> bool:
        return looks_like_angle(path, field_type)


FAMILIES.register(Angle.name, Angle())
