"""Does a replayed trajectory match the recorded one?

The replayed trajectory is interpolated (linearly, in x and y) onto the
recorded trajectory's timestamps over the span both cover; the result is the
lock-step Euclidean distance √Σ(dx²+dy²) over those points and the largest
single point error. Edge cases are decided here, once:

- both empty: a match (distance 0);
- one empty, the other not: no match (distance ∞);
- a single recorded or replayed point, or no overlap in time: the first
  points are compared;
- replayed times not strictly increasing: compared index by index over the
  shorter length (interpolation would be meaningless).
"""

from __future__ import annotations

import math
from itertools import pairwise
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

Point = tuple[float, float, float]  # x, y, t (absolute seconds)


@dataclass(frozen=True)
class Comparison:
    distance: float  # lock-step Euclidean distance, m
    max_error: float  # largest single point error, m
    points: int  # how many points were compared
    how: str  # "interpolated", "first point", "index", "both empty", "one empty"

    def within(self, threshold: float) -> bool:
        return self.distance <= threshold


def compare(replayed: Sequence[Point], recorded: Sequence[Point]) -> Comparison:
    if not replayed and not recorded:
        return Comparison(0.0, 0.0, 0, "both empty")
    if not replayed or not recorded:
        return Comparison(math.inf, math.inf, 0, "one empty")
    rep = np.asarray(replayed, dtype=float)
    rec = np.asarray(recorded, dtype=float)
    if not (np.isfinite(rep).all() and np.isfinite(rec).all()):
        exact = rep.shape == rec.shape and bool(np.array_equal(rep, rec, equal_nan=True))
        return Comparison(0.0 if exact else math.inf, 0.0 if exact else math.inf, len(rec), "non-finite")
    if len(rep) == 1 or len(rec) == 1:
        return _points(rep[:1], rec[:1], "first point")
    if not np.all(np.diff(rep[:, 2]) > 0):
        n = min(len(rep), len(rec))
        return _points(rep[:n], rec[:n], "index")
    start, end = max(rep[0, 2], rec[0, 2]), min(rep[-1, 2], rec[-1, 2])
    inside = rec[(rec[:, 2] >= start) & (rec[:, 2] <= end)]
    if len(inside) == 0:
        return _points(rep[:1], rec[:1], "first point")
    x = np.interp(inside[:, 2], rep[:, 2], rep[:, 0])
    y = np.interp(inside[:, 2], rep[:, 2], rep[:, 1])
    return _errors(np.hypot(x - inside[:, 0], y - inside[:, 1]), "interpolated")


def identical(points: Sequence[Point]) -> Comparison:
    """``compare(points, points)`` without the arithmetic: the same case, and no error anywhere.

    For a replayed trajectory known to equal the recorded one (extraction
    checks a replayed output field for field first, and most are): the
    interpolation in ``compare`` costs ten times the check, and at the
    recorded points' own times it reproduces them exactly (``np.interp`` at
    a node). tests/test_deft_validator.py holds the two to the same result.
    """
    if not points:
        return Comparison(0.0, 0.0, 0, "both empty")
    if not all(math.isfinite(value) for point in points for value in point):
        return Comparison(0.0, 0.0, len(points), "non-finite")
    if len(points) == 1:
        return Comparison(0.0, 0.0, 1, "first point")
    if not all(a[2] < b[2] for a, b in pairwise(points)):
        return Comparison(0.0, 0.0, len(points), "index")
    return Comparison(0.0, 0.0, len(points), "interpolated")


def _points(a: np.ndarray, b: np.ndarray, how: str) -> Comparison:
    return _errors(np.hypot(a[:, 0] - b[:, 0], a[:, 1] - b[:, 1]), how)


def _errors(d: np.ndarray, how: str) -> Comparison:
    return Comparison(float(math.sqrt(float(np.sum(d * d)))), float(np.max(d)), int(len(d)), how)


# ------------------------------------------------------------ any module's output, field by field


def flatten(message: object, ignore: Sequence[str] = ()) -> dict[str, object]:
    """Leaf path → value of a decoded message (``a.b[2].c``), without the ``ignore`` paths and what lies below them."""
    out: dict[str, object] = {}

    def walk(value: object, path: str) -> None:
        if path and any(path == skip or path.startswith(skip + ".") or path.startswith(skip + "[")
                        for skip in ignore):
            return
        if isinstance(value, dict):
            for key in sorted(value):
                walk(value[key], f"{path}.{key}" if path else str(key))
        elif isinstance(value, list):
            for i, item in enumerate(value):
                walk(item, f"{path}[{i}]")
            if not value:
                out[path] = []
        else:
            out[path] = value
    walk(message, "")
    return out


def _leaf_error(a: object, b: object) -> float:
    numeric = (int, float)
    if isinstance(a, numeric) and isinstance(b, numeric) and not isinstance(a, bool) and not isinstance(b, bool):
        if math.isnan(a) or math.isnan(b):
            return 0.0 if math.isnan(a) and math.isnan(b) else math.inf
        if math.isinf(a) or math.isinf(b):
            return 0.0 if a == b else math.inf
        return abs(float(a) - float(b))
    return 0.0 if type(a) is type(b) and a == b else math.inf


def compare_messages(replayed: object, recorded: object, ignore: Sequence[str] = ()) -> Comparison:
    """A module's replayed output against the recorded one: √Σ of the numeric fields' differences.

    A missing output on one side only, a field on one side only or a
    non-numeric field that differs is no match (∞); NaN matches NaN.
    """
    if replayed is None and recorded is None:
        return Comparison(0.0, 0.0, 0, "both empty")
    if replayed is None or recorded is None:
        return Comparison(math.inf, math.inf, 0, "one empty")
    a, b = flatten(replayed, ignore), flatten(recorded, ignore)
    if a.keys() != b.keys():
        return Comparison(math.inf, math.inf, len(b), "fields differ")
    errors = [_leaf_error(a[k], b[k]) for k in b]
    if not errors:
        return Comparison(0.0, 0.0, 0, "fields")
    worst = max(errors)
    distance = math.inf if math.isinf(worst) else math.sqrt(sum(e * e for e in errors))
    return Comparison(distance, worst, len(errors), "fields")


def differing_fields(replayed: object, recorded: object, ignore: Sequence[str] = (), limit: int = 6
                     ) -> list[tuple[str, object, object]]:
    """(path, recorded, replayed) of the first fields that differ (for a failing test's report)."""
    a, b = flatten(replayed, ignore), flatten(recorded, ignore)
    out: list[tuple[str, object, object]] = []
    for key in list(b) + [k for k in a if k not in b]:
        if key not in a or key not in b or _leaf_error(a[key], b[key]) > 0:
            out.append((key, b.get(key, "—"), a.get(key, "—")))
            if len(out) == limit:
                break
    return out
