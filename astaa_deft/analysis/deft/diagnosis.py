"""Why outputs do not reproduce: which fields of a module's output differ, how, and the ``ignore:`` line to add.

An extraction judges each kept frame by comparing the replayed output with
the recorded one; a module compared field by field keeps, on that
comparison, the fields that differed (``validator.FieldDifference``). This
reads those comparisons, one per output, and says per field how often it
differs and how:

- only in the recorded output (the node adds it — a ``header.frame_id`` —
  and the module's step does not return it) or only in the replayed one:
  no frame can ever match while the comparison keeps it;
- by the same amount in every output (a constant offset) or with the same
  two values every time: a convention of the node's, not the module's result;
- in every output by varying amounts: a clock, a counter or noise of the
  node's own, or what the module computes when its frames or its state
  differ from the run's — told apart only by the spec's ``brittle:``
  declaration (else both readings are given);
- by rounding only (≤ 1e-9): a matter for θ, not for ``ignore:``;
- in some outputs only: those frames (or the state) differ; not for ``ignore:``.

The line to add is the spec's ``ignore:`` list with the fields that never
match. With the kept frames' comparisons it also counts the outputs those
frames would match once the line is added. Pure logic: no I/O.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field

from astaa_deft.model.errors import did_you_mean
from astaa_deft.analysis.deft.validator import Comparison, FieldDifference, flatten, wildcard_path

ROUNDING = 1e-9  # a field off by no more than this is rounding (the extraction's near misses; set θ for it)
REPLAY_ERROR = "__replay_error__"  # the field a replayed output carries when the module's step raised
SHOWN_FIELDS = 8  # fields printed (the summary's JSON holds them all)

# How a field differs.
RECORDED_ONLY = "recorded only"
REPLAYED_ONLY = "replayed only"
OFFSET = "constant offset"
CONSTANT = "constant values"
ALWAYS = "always different"
ROUNDED = "rounding"
SOMETIMES = "sometimes"
HOWS = (RECORDED_ONLY, REPLAYED_ONLY, OFFSET, CONSTANT, ALWAYS, ROUNDED, SOMETIMES)  # the order they are shown in

FIELD_HOWS = ("fields", "fields differ")  # comparisons made field by field
NOTHING_ON_ONE_SIDE = ("one empty", "no answer")


@dataclass(frozen=True, kw_only=True)
class FieldFinding:
    """One output field that differs in at least one output not reproduced."""

    path: str  # as ``ignore:`` names it (array indices ``[*]``)
    how: str  # RECORDED_ONLY, REPLAYED_ONLY, OFFSET, CONSTANT, ALWAYS, ROUNDED or SOMETIMES
    differs: int  # outputs compared in which it differs
    blocking: int  # of the outputs not reproduced, those in which it differs
    detail: str  # what was seen, in words (values, the offset, the spread)
    in_line: bool  # the ``ignore:`` line to add names it (it never matches)


@dataclass(frozen=True, kw_only=True)
class Diagnosis:
    """Why an extraction's outputs do not reproduce (``diagnose``)."""

    threshold: float  # θ the outputs were judged at
    judged: int  # outputs judged (frames with an output to compare, or an answer where none was recorded)
    not_reproduced: int  # of those, not within θ
    compared: int  # outputs compared field by field (the others: trajectories, nothing on one side, a raise)
    fields: tuple[FieldFinding, ...] = ()
    spec_ignore: tuple[str, ...] = ()  # the spec's own ``ignore:`` entries
    ignore: tuple[str, ...] = ()  # the ``ignore:`` list to write (the spec's own first); (): nothing to add
    maybe: tuple[str, ...] = ()  # fields that never match by varying amounts, not in ``ignore`` (see module doc)
    reproduced_with_line: int = 0  # outputs not reproduced that the frames kept match within θ with ``ignore``
    where: str = ""  # the module's place in the spec (``replay.modules[0]``)
    unanswered: int = 0  # outputs not reproduced with nothing on one side (no answer, or none recorded)
    raised: int = 0  # outputs not reproduced because the module's step raised
    raised_example: str = ""
    trajectory_distances: tuple[float, ...] = ()  # a planner's outputs not reproduced: their distances, m
    unknown_ignores: tuple[tuple[str, str], ...] = ()  # (an ``ignore:`` entry naming no field, a hint)

    @property
    def ignore_line(self) -> str | None:
        """``ignore: [a, b]`` to put in the module's spec entry, or None when no field never matches."""
        return f"ignore: [{', '.join(self.ignore)}]" if self.ignore else None

    def lines(self, spec_path: str = "the spec") -> list[str]:
        """The diagnosis as the ``extract`` command prints it."""
        unit = " m" if self.trajectory_distances else ""
        out = [f"why outputs do not reproduce: {self.not_reproduced} of {self.judged} output(s) not within "
               f"θ = {self.threshold:g}{unit}"
               + (f" ({self.compared} compared field by field)" if self.compared else "")]
        width = max((len(f.path) for f in self.fields[:SHOWN_FIELDS]), default=0)
        for found in self.fields[:SHOWN_FIELDS]:
            out.append(f"  {found.path:<{width}}  {found.detail}")
        if len(self.fields) > SHOWN_FIELDS:
            out.append(f"  … and {len(self.fields) - SHOWN_FIELDS} more field(s) that differ")
        if self.raised:
            out.append(f"  the module's step raised on {self.raised} of them (e.g. {self.raised_example})")
        if self.unanswered:
            out.append(f"  {self.unanswered} of them have nothing on one side (the module answered nothing where "
                       f"an output was recorded, or answered where none was)")
        if self.trajectory_distances:
            near = sorted(self.trajectory_distances)
            out.append(f"  compared as trajectories (the points' x, y and t; 'ignore:' does not apply): off by "
                       f"{near[0]:.3g} to {near[-1]:.3g} m (median {statistics.median(near):.3g} m)")
        for entry, hint in self.unknown_ignores:
            out.append(f"  'ignore: {entry}' names no field of the recorded outputs{' (' + hint + ')' if hint else ''}")
        if self.ignore_line is not None:
            place = f"{self.where} of {spec_path}" if self.where else spec_path
            verb = "replace its ignore: with" if self.spec_ignore else "write"
            out.append(f"in {place}, {verb} (then extract again):  {self.ignore_line}")
            out.append(f"  (with it, the frames kept match {self.reproduced_with_line} of the {self.not_reproduced} "
                       f"output(s) not reproduced now)")
        for path in self.maybe:
            both = ", ".join((*(self.ignore or self.spec_ignore), path))
            out.append(f"if {path} is a clock, a counter or noise of the node's own (not what the module computes), "
                       f"ignore it too: ignore: [{both}]; if it is the module's result, its frames or its state "
                       f"differ from the run's")
        if not self.fields and not self.raised and not self.unanswered and not self.trajectory_distances:
            out.append("  no field differs beyond what was compared (the comparison described no field)")
        return out

    def as_json(self) -> dict[str, object]:
        """The diagnosis as the extraction's summary stores it."""
        return {
            "threshold": self.threshold, "judged": self.judged, "not_reproduced": self.not_reproduced,
            "compared": self.compared, "ignore_line": self.ignore_line, "ignore": list(self.ignore),
            "maybe_ignore": list(self.maybe), "reproduced_with_line": self.reproduced_with_line,
            "where": self.where, "unanswered": self.unanswered, "raised": self.raised,
            "fields": [{"path": f.path, "how": f.how, "differs": f.differs, "blocking": f.blocking,
                        "detail": f.detail, "in_line": f.in_line} for f in self.fields],
            "unknown_ignores": [list(pair) for pair in self.unknown_ignores],
        }


@dataclass(kw_only=True)
class _Seen:
    """What the comparisons say about one field."""

    differs: int = 0
    blocking: int = 0
    sides: set[str] = field(default_factory=set)
    numeric: bool = True  # every difference was between two finite numbers
    offsets: set[float | None] = field(default_factory=set)  # per output: its offset if uniform, else None
    largest: float = 0.0  # largest |Δ| of a numeric difference
    pairs: dict[tuple[str, str], int] = field(default_factory=dict)  # (recorded, replayed) → outputs, a few

    def add(self, difference: FieldDifference, blocking: bool) -> None:
        self.differs += 1
        self.blocking += blocking
        self.sides.add(difference.side)
        self.numeric = self.numeric and difference.delta is not None
        self.offsets.add(difference.delta if difference.uniform else None)
        if difference.delta is not None:
            self.largest = max(self.largest, abs(difference.delta),
                               math.sqrt(difference.squared) if math.isfinite(difference.squared) else 0.0)
        pair = (difference.recorded, difference.replayed)
        if pair in self.pairs or len(self.pairs) < 4:
            self.pairs[pair] = self.pairs.get(pair, 0) + 1


def diagnose(comparisons: Sequence[Comparison], *, threshold: float, ignore: Sequence[str] = (), where: str = "",
             brittle: Callable[[str], bool] = lambda path: False, recorded: Sequence[object] = ()
             ) -> Diagnosis | None:
    """Why the outputs whose ``comparisons`` (one per output judged, in order) are not within ``threshold``
    do not reproduce; None when every output does.

    ``ignore``: the spec's ``ignore:`` entries (the line to add starts with
    them); ``where``: the module's place in the spec; ``brittle(path)``: the
    spec declares the output field brittle (a stamp or a counter, see
    docs/spec.md), so a field of it that differs in every output by varying
    amounts goes into the line; ``recorded``: a few recorded outputs
    (decoded), to find ``ignore:`` entries that name no field.
    """
    judged = [c for c in comparisons if c.how != "silent"]
    failing = [c for c in judged if not c.within(threshold)]
    if not failing:
        return None
    raised = [c for c in judged if _raised(c)]
    by_field = [c for c in judged if c.how in FIELD_HOWS and not _raised(c)]
    seen: dict[str, _Seen] = {}
    for c in by_field:
        for difference in c.fields:
            seen.setdefault(difference.path, _Seen()).add(difference, not c.within(threshold))
    findings = [_finding(path, s, len(by_field), brittle) for path, s in seen.items() if s.blocking]
    findings.sort(key=lambda f: (not f.in_line, HOWS.index(f.how), -f.blocking, f.path))
    new = [f.path for f in findings if f.in_line and f.path not in ignore]
    line = (*ignore, *new) if new else ()
    failing_by_field = [c for c in failing if c.how in FIELD_HOWS and not _raised(c)]
    examples = [_replay_error(c) for c in raised if not c.within(threshold)]
    return Diagnosis(
        threshold=threshold, judged=len(judged), not_reproduced=len(failing), compared=len(by_field),
        fields=tuple(findings), spec_ignore=tuple(ignore), ignore=line, where=where,
        maybe=tuple(f.path for f in findings if f.how == ALWAYS and not f.in_line),
        reproduced_with_line=sum(_within_without(c, set(new), threshold) for c in failing_by_field) if new else 0,
        unanswered=sum(1 for c in failing if c.how in NOTHING_ON_ONE_SIDE),
        raised=len(examples), raised_example=next((e for e in examples if e), ""),
        trajectory_distances=tuple(c.distance for c in failing
                                   if c.how not in (*FIELD_HOWS, *NOTHING_ON_ONE_SIDE) and not _raised(c)),
        unknown_ignores=unmatched_ignores(recorded, ignore))


def _raised(comparison: Comparison) -> bool:
    """The module's step raised on this frame (a per-trigger module's error, or a replayed output that says so)."""
    return comparison.how == "error" or any(f.path == REPLAY_ERROR for f in comparison.fields)


def _finding(path: str, seen: _Seen, compared: int, brittle: Callable[[str], bool]) -> FieldFinding:
    """How one field differs, in words, and whether the line names it."""
    every = seen.differs == compared
    often = f"in {seen.differs} of {compared} output(s)" if not every else f"in every output ({compared})"
    numeric = seen.numeric and seen.sides == {"both"}
    example = _example(seen)
    if seen.sides == {"recorded"}:
        return FieldFinding(path=path, how=RECORDED_ONLY, differs=seen.differs, blocking=seen.blocking,
                            in_line=every, detail=f"only in the recorded output (the node publishes it, the "
                            f"module's step does not return it), {often}{example}")
    if seen.sides == {"replayed"}:
        return FieldFinding(path=path, how=REPLAYED_ONLY, differs=seen.differs, blocking=seen.blocking,
                            in_line=every, detail=f"only in the replayed output (the module's step returns it; "
                            f"the recorded outputs lack it), {often}{example}")
    if numeric and seen.largest <= ROUNDING:
        return FieldFinding(path=path, how=ROUNDED, differs=seen.differs, blocking=seen.blocking, in_line=False,
                            detail=f"off by rounding only (|Δ| ≤ {seen.largest:.3g}), {often}: set θ for it, "
                            f"not ignore:")
    if every and numeric and len(seen.offsets) == 1 and None not in seen.offsets:
        offset = next(iter(seen.offsets))
        assert offset is not None
        return FieldFinding(path=path, how=OFFSET, differs=seen.differs, blocking=seen.blocking, in_line=True,
                            detail=f"a constant offset: replayed − recorded = {offset:+.6g} {often}")
    if every and not numeric and len(seen.pairs) == 1:
        return FieldFinding(path=path, how=CONSTANT, differs=seen.differs, blocking=seen.blocking, in_line=True,
                            detail=f"the same two values {often}{example}")
    spread = f" (|Δ| up to {seen.largest:.3g})" if numeric else example
    if every:
        declared = brittle(path)
        return FieldFinding(path=path, how=ALWAYS, differs=seen.differs, blocking=seen.blocking, in_line=declared,
                            detail=f"differs {often}, by varying amounts{spread}"
                            + (" — the spec declares it brittle (a stamp or a counter)" if declared else ""))
    return FieldFinding(path=path, how=SOMETIMES, differs=seen.differs, blocking=seen.blocking, in_line=False,
                        detail=f"differs {often}{spread}: in those the frame or the module's state differs from "
                        f"the run's (not a field to ignore)")


def _example(seen: _Seen) -> str:
    """``: recorded 'map', replayed ''`` for the values seen most often."""
    (recorded, replayed), _ = max(seen.pairs.items(), key=lambda item: item[1])
    parts = [f"recorded {recorded}" if recorded else "", f"replayed {replayed}" if replayed else ""]
    shown = ", ".join(p for p in parts if p)
    return f": e.g. {shown}" if shown else ""


def _within_without(comparison: Comparison, ignored: set[str], threshold: float) -> bool:
    """The output would be within θ if ``ignored`` fields were not compared (unknown: False)."""
    if comparison.fields_left_out:
        return False
    remaining = math.fsum(f.squared for f in comparison.fields if f.path not in ignored)
    return math.sqrt(remaining) <= threshold


def _replay_error(comparison: Comparison) -> str:
    found = next((f for f in comparison.fields if f.path == REPLAY_ERROR), None)
    return found.replayed.strip("'\"") if found is not None else ""


def unmatched_ignores(recorded: Iterable[object], ignore: Sequence[str]) -> tuple[tuple[str, str], ...]:
    """The ``ignore`` entries that skip nothing in any of the ``recorded`` outputs, each with a hint (a close
    field path), or () when there is no output to look at."""
    messages = [m for m in recorded if isinstance(m, Mapping)]
    if not messages or not ignore:
        return ()
    whole = [flatten(m) for m in messages]
    out = []
    for entry in ignore:
        if any(len(flatten(m, (entry,))) < len(leaves) for m, leaves in zip(messages, whole, strict=True)):
            continue
        known = sorted({p for leaves in whole for leaf in leaves for p in _prefixes(leaf)})
        out.append((entry, did_you_mean(entry, known)))
    return tuple(out)


def _prefixes(leaf: str) -> list[str]:
    """``a[2].b.c`` → ``a``, ``a[*]``, ``a[*].b``, ``a[*].b.c``: what an ``ignore:`` entry could name."""
    path = wildcard_path(leaf)
    cuts = [i for i, ch in enumerate(path) if ch in ".["] + [len(path)]
    return [path[:i] for i in cuts if i]
