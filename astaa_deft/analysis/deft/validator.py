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
import re
from functools import lru_cache
from itertools import pairwise
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

Point = tuple[float, float, float]  # x, y, t (absolute seconds)


@dataclass(frozen=True, kw_only=True)
class FieldDifference:
    """How one field of a module's output differs between the replayed and the recorded message.

    Array elements count as one field (``path`` writes each index ``[*]``):
    what a spec's ``ignore:`` names to skip them all. Kept on the comparison
    so that an extraction can say why outputs do not reproduce (diagnosis.py).
    """

    path: str  # the leaf's path, each array index written [*]
    side: str  # "both"; "recorded": only in the recorded output; "replayed": only in the replayed one
    leaves: int  # leaves under ``path`` that differ (array elements)
    delta: float | None  # both sides numeric and finite: replayed − recorded of the first leaf; else None
    uniform: bool  # every leaf that differs, differs by ``delta``
    squared: float  # Σ of those leaves' squared differences (∞: not numeric, or on one side only)
    recorded: str  # the first differing leaf's recorded value, shortened ("" when only replayed)
    replayed: str  # its replayed value, shortened ("" when only recorded)


MAX_FIELD_DIFFERENCES = 24  # fields described per comparison (a message's other differing fields are counted)


@dataclass(frozen=True, kw_only=True)
class Comparison:
    distance: float  # lock-step Euclidean distance, m
    max_error: float  # largest single point error, m
    points: int  # how many points were compared
    how: str  # "interpolated", "first point", "index", "both empty", "one empty"
    # A module compared field by field: the fields that differ (at most MAX_FIELD_DIFFERENCES), and how many
    # other differing fields are not described.
    fields: tuple[FieldDifference, ...] = ()
    fields_left_out: int = 0

    def within(self, threshold: float) -> bool:
        return self.distance <= threshold


def compare(replayed: Sequence[Point], recorded: Sequence[Point]) -> Comparison:
    if not replayed and not recorded:
        return Comparison(distance=0.0, max_error=0.0, points=0, how="both empty")
    if not replayed or not recorded:
        return Comparison(distance=math.inf, max_error=math.inf, points=0, how="one empty")
    rep = np.asarray(replayed, dtype=float)
    rec = np.asarray(recorded, dtype=float)
    if not (np.isfinite(rep).all() and np.isfinite(rec).all()):
        exact = rep.shape == rec.shape and bool(np.array_equal(rep, rec, equal_nan=True))
        return Comparison(distance=0.0 if exact else math.inf, max_error=0.0 if exact else math.inf, points=len(rec),
                          how="non-finite")
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
        return Comparison(distance=0.0, max_error=0.0, points=0, how="both empty")
    if not all(math.isfinite(value) for point in points for value in point):
        return Comparison(distance=0.0, max_error=0.0, points=len(points), how="non-finite")
    if len(points) == 1:
        return Comparison(distance=0.0, max_error=0.0, points=1, how="first point")
    if not all(a[2] < b[2] for a, b in pairwise(points)):
        return Comparison(distance=0.0, max_error=0.0, points=len(points), how="index")
    return Comparison(distance=0.0, max_error=0.0, points=len(points), how="interpolated")


def _points(a: np.ndarray, b: np.ndarray, how: str) -> Comparison:
    return _errors(np.hypot(a[:, 0] - b[:, 0], a[:, 1] - b[:, 1]), how)


def _errors(d: np.ndarray, how: str) -> Comparison:
    return Comparison(distance=float(math.sqrt(float(np.sum(d * d)))), max_error=float(np.max(d)), points=int(len(d)),
                      how=how)


# ------------------------------------------------------------ any module's output, field by field


def flatten(message: object, ignore: Sequence[str] = ()) -> dict[str, object]:
    """Leaf path → value of a decoded message (``a.b[2].c``), without the ``ignore`` paths and what lies below them.

    An ``ignore`` path names a leaf, a whole struct (``header``: every field
    in it) or an array (``points``: every element); ``[*]`` stands for every
    index (``objects[*].header.frame_id``).
    """
    out: dict[str, object] = {}
    plain, wild = _ignore_rules(tuple(ignore))

    def walk(value: object, path: str) -> None:
        if path and (any(path == skip or path.startswith(skip + ".") or path.startswith(skip + "[")
                         for skip in plain) or (wild is not None and wild.match(path))):
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


@lru_cache(maxsize=256)
def _ignore_rules(ignore: tuple[str, ...]) -> tuple[tuple[str, ...], re.Pattern[str] | None]:
    """The ``ignore`` paths without ``[*]``, and one pattern matching any path at or below one with ``[*]``."""
    plain = tuple(skip for skip in ignore if "[*]" not in skip)
    wild = [re.escape(skip).replace(re.escape("[*]"), r"\[[0-9]+\]") for skip in ignore if "[*]" in skip]
    return plain, re.compile(f"(?:{'|'.join(wild)})(?:$|[.\\[])") if wild else None


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
        return Comparison(distance=0.0, max_error=0.0, points=0, how="both empty")
    if replayed is None or recorded is None:
        return Comparison(distance=math.inf, max_error=math.inf, points=0, how="one empty")
    a, b = flatten(replayed, ignore), flatten(recorded, ignore)
    if a.keys() != b.keys():
        described, left_out = field_differences(a, b)
        return Comparison(distance=math.inf, max_error=math.inf, points=len(b), how="fields differ", fields=described,
                          fields_left_out=left_out)
    errors = [_leaf_error(a[k], b[k]) for k in b]
    if not errors:
        return Comparison(distance=0.0, max_error=0.0, points=0, how="fields")
    worst = max(errors)
    if worst == 0.0:
        return Comparison(distance=0.0, max_error=0.0, points=len(errors), how="fields")
    distance = math.inf if math.isinf(worst) else math.sqrt(sum(e * e for e in errors))
    described, left_out = field_differences(a, b, errors)
    return Comparison(distance=distance, max_error=worst, points=len(errors), how="fields", fields=described,
                      fields_left_out=left_out)


def field_differences(replayed: Mapping[str, object], recorded: Mapping[str, object],
                      errors: Sequence[float] | None = None) -> tuple[tuple[FieldDifference, ...], int]:
    """The fields that differ between two flattened messages (array elements together): those only replayed,
    then the others in the recorded message's order (at most MAX_FIELD_DIFFERENCES of them, how many more).

    ``errors``: each recorded leaf's error (``_leaf_error``), when known.
    """
    groups: dict[str, list[tuple[str, object, object, float]]] = {}
    for key in replayed:  # first: a step that raised answers one field of its own, never cut off
        if key not in recorded:
            groups.setdefault(wildcard_path(key), []).append(("replayed", None, replayed[key], math.inf))
    for i, key in enumerate(recorded):
        if key not in replayed:
            groups.setdefault(wildcard_path(key), []).append(("recorded", recorded[key], None, math.inf))
            continue
        error = errors[i] if errors is not None else _leaf_error(replayed[key], recorded[key])
        if error > 0.0:
            groups.setdefault(wildcard_path(key), []).append(("both", recorded[key], replayed[key], error))
    out = []
    for path, leaves in list(groups.items())[:MAX_FIELD_DIFFERENCES]:
        sides = {side for side, *_ in leaves}
        side, first_recorded, first_replayed, _ = leaves[0]
        deltas = [_delta(rep, rec) for kind, rec, rep, _ in leaves]
        out.append(FieldDifference(
            path=path, side=side if len(sides) == 1 else "both", leaves=len(leaves), delta=deltas[0],
            uniform=deltas[0] is not None and all(d == deltas[0] for d in deltas),
            squared=math.fsum(e * e for *_, e in leaves) if all(math.isfinite(e) for *_, e in leaves) else math.inf,
            recorded="" if side == "replayed" else _shown(first_recorded),
            replayed="" if side == "recorded" else _shown(first_replayed)))
    return tuple(out), max(0, len(groups) - MAX_FIELD_DIFFERENCES)


_INDEX = re.compile(r"\[[0-9]+\]")


@lru_cache(maxsize=4096)
def wildcard_path(path: str) -> str:
    """``a[3].b[0]`` → ``a[*].b[*]``: every element of an array is one field."""
    return _INDEX.sub("[*]", path)


def _delta(replayed: object, recorded: object) -> float | None:
    """replayed − recorded for two finite numbers (not booleans), else None."""
    numeric = (int, float)
    if (isinstance(replayed, numeric) and isinstance(recorded, numeric) and not isinstance(replayed, bool)
            and not isinstance(recorded, bool) and math.isfinite(replayed) and math.isfinite(recorded)):
        return float(replayed) - float(recorded)
    return None


def _shown(value: object, width: int = 40) -> str:
    """A leaf's value for a report: its repr, cut to ``width`` characters."""
    text = repr(value)
    return text if len(text) <= width else text[:width - 1] + "…"


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
