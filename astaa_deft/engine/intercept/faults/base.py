"""The fault family interface, and what the families share: targets, windows, one-policy test cases.

A fault family is one module of this package holding one :class:`FaultFamily`
subclass that registers an instance in ``FAMILIES``. It says:

* ``weight``: its share of the weighted draws (next to the others' weights;
  ``astaa-deft generate`` and a campaign's weighted cases use them), and
  ``rank``, its place in the draw (a family added later takes a higher rank,
  so the families before it draw the same cases from the same seed);
* ``targets``: where it can act, by channel (fields with the values it would
  put there, or channels), from a spec and a dictionary (:class:`Sources`);
* ``draw``: one test case on those targets, with a seeded RNG, inside a
  :class:`Scene` (the run's duration, anchor and latest start);
* ``probe``: the test case of one visit of a target in a coverage round
  (semantic families; the exceptional-value families' rounds are the
  generator's own, :func:`astaa_deft.engine.intercept.generate.coverage_round`);
* its description, written by ``draw`` into the test case.

``owns`` lists dictionary entries only this family draws: the exceptional
value families leave them out, so adding a family's entries to the default
dictionary does not change what the others draw.
"""

from __future__ import annotations

import random
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import ClassVar

from astaa_deft.io.codecs import get_codec
from astaa_deft.model.fields import FieldPath, is_brittle, leaf_fields, type_at
from astaa_deft.model.sut import Channel, FieldType, Spec
from astaa_deft.engine.intercept.actions.base import ActionConfig
from astaa_deft.engine.intercept.actions.set import Assignment, Set
from astaa_deft.engine.intercept.dictionary import Dictionary, Entry, FieldSite, field_site
from astaa_deft.engine.intercept.testcase import Policy, Selection, TestCase, Window

SUSTAINED_SECONDS = (1.0, 5.0)  # a held value: every message of a window this long …
SUSTAINED_MESSAGES = (5, 50)  # … or this many messages in a row
# Field names that are bookkeeping when they sit in a header-like struct.
HEADER_BOOKKEEPING = frozenset({"stamp", "timestamp", "seq", "sequence", "frame_id"})


@dataclass(frozen=True, kw_only=True)
class Target:
    """A field a family may mutate, with the dictionary values it would put there.

    ``partner``: a second field the fault involves (the sibling of a swap).
    """

    channel: Channel
    path: FieldPath
    site: FieldSite
    values: tuple[Entry, ...]
    partner: FieldPath | None = None


Targets = dict[str, list[Target]]  # by channel name


@dataclass(frozen=True, kw_only=True)
class Sources:
    """What families find their targets in: the spec, the dictionary, and the shared finds.

    ``exceptional``: the exceptional-value targets by channel (every non-brittle
    leaf of a consumed channel with a usable value of its group, entries owned
    by a family left out); ``stamps``: the stamp and sequence targets.
    """

    spec: Spec
    dictionary: Dictionary
    include_brittle: bool
    exceptional: Targets
    stamps: Targets


@dataclass(frozen=True)
class Scene:
    """Where a case's window goes: inside ``duration`` s, counted from ``anchor``'s first message (None: the
    run's start), opening by ``latest`` s (None: 80 % of ``duration``)."""

    duration: float
    anchor: str | None = None
    latest: float | None = None

    def start(self, rng: random.Random) -> float:
        return round(rng.uniform(0.0, self.duration * 0.8 if self.latest is None else self.latest), 1)


class FaultFamily(ABC):
    """One kind of fault the generator draws (see the module docstring)."""

    name: ClassVar[str]
    weight: ClassVar[int]  # share of the weighted draws, next to the other families' weights
    rank: ClassVar[int]  # place in the weighted draw: a new family takes the next free rank
    campaign_only: ClassVar[bool] = False  # drawn only where message faults are asked for (campaigns)
    semantic: ClassVar[bool] = False  # a plausible-but-wrong family: probed in the campaign's semantic rounds
    owns: ClassVar[tuple[str, ...]] = ()  # dictionary keys only this family draws

    @abstractmethod
    def targets(self, sources: Sources) -> Targets:
        """Where this family can act, by channel (channels without a target left out)."""

    @abstractmethod
    def draw(self, testcase_id: str, rng: random.Random, targets: Targets, scene: Scene) -> TestCase:
        """One test case on ``targets`` (never empty)."""

    def probe(self, testcase_id: str, rng: random.Random, target: Target, *, visit: int, scene: Scene) -> TestCase:
        """The test case of the ``visit``-th visit (from 0) of ``target`` in a coverage round; default: a draw
        on that target alone."""
        return self.draw(testcase_id, rng, {target.channel.name: [target]}, scene)

    def visits(self, target: Target) -> int:
        """How many probes of ``target`` differ before they repeat (default: one per value, at least one)."""
        return max(1, len(target.values))

    def __repr__(self) -> str:
        return f"<fault family {self.name}>"


# ---------------------------------------------------------------- what may be mutated

def is_generation_brittle(spec: Spec, type_name: str, path: FieldPath) -> bool:
    """The spec's brittle fields, plus stamps and sequence numbers of header-like structs.

    Header-like: a struct whose field name or type name contains "header"
    (``header.stamp``, ``meta.seq`` where ``meta`` is a ``Header``), or the
    message type itself when its name does.
    """
    if is_brittle(spec.types, type_name, path, spec.brittle):
        return True
    segments = path.segments
    for index, segment in enumerate(segments):
        if type(segment) is not str or segment.lower() not in HEADER_BOOKKEEPING:
            continue
        owner_type = type_name if index == 0 else type_at(spec.types, type_name, FieldPath(segments[:index])).ref
        owner_name = next((s for s in reversed(segments[:index]) if type(s) is str), "")
        if "header" in str(owner_type).lower() or "header" in owner_name.lower():
            return True
    return False


def consumed_fields(sources: Sources) -> Iterable[tuple[Channel, FieldPath, FieldType]]:
    """Every (channel, leaf field, its type) a family may touch: channels with consumers, brittle fields left
    out unless asked; in spec order."""
    spec = sources.spec
    for channel in spec.channels:
        if not channel.consumers:  # nobody would receive the mutation
            continue
        for path, field_type in leaf_fields(spec.types, channel.type):
            if sources.include_brittle or not is_generation_brittle(spec, channel.type, path):
                yield channel, path, field_type


def every_consumed_field(sources: Sources) -> Targets:
    """Every field of :func:`consumed_fields` as a target with no values (families whose fault is not a value)."""
    found: Targets = {}
    for channel, path, _field_type in consumed_fields(sources):
        site = field_site(sources.spec.types, channel.type, path)
        found.setdefault(channel.name, []).append(Target(channel=channel, path=path, site=site, values=()))
    return found


def entry_targets(sources: Sources, keys_of_kind: dict[str, Sequence[str]],
                  accept: Callable[[Channel, FieldPath, FieldType], bool] | None = None) -> Targets:
    """Targets whose values are the dictionary ``keys_of_kind[field kind]`` the field can take (in that
    order; keys missing from the dictionary left out). ``accept(channel, path, field_type)``, if given,
    narrows the fields."""
    dictionary = sources.dictionary
    found: Targets = {}
    for channel, path, field_type in consumed_fields(sources):
        keys = keys_of_kind.get(field_type.kind)
        if not keys or (accept is not None and not accept(channel, path, field_type)):
            continue
        site = field_site(sources.spec.types, channel.type, path)
        entries = [dictionary.get(key) for key in keys if key in dictionary]
        usable, _skipped = dictionary.usable(site, get_codec(channel.encoding), entries)
        if usable:
            found.setdefault(channel.name,
                             []).append(Target(channel=channel, path=path, site=site, values=tuple(usable)))
    return found


# ---------------------------------------------------------------- building one test case

def held(rng: random.Random, start: float, duration: float) -> tuple[float, Selection]:
    """Where a held value's window ends and what it selects: every message of a 1–5 s window, or the
    next 5–50 messages (the window stays open until ``duration``; the limit ends it)."""
    if rng.random() < 0.5:
        return min(round(start + rng.uniform(*SUSTAINED_SECONDS), 1), duration), Selection()
    return duration, Selection(limit=rng.randint(*SUSTAINED_MESSAGES))


def once_or_held(rng: random.Random, start: float, duration: float) -> tuple[float, Selection]:
    """One message (half of the draws) or held (:func:`held`)."""
    return held(rng, start, duration) if rng.random() < 0.5 else (duration, Selection(limit=1))


@dataclass(frozen=True)
class Span:
    """A policy's window from ``start`` s to ``end`` s (at least 0.1 s), selecting ``selection``; its times
    count from ``anchor``'s first message (None: from the run's start)."""

    start: float
    end: float
    selection: Selection
    anchor: str | None

    def window(self) -> Window:
        return Window(self.start, max(self.end, round(self.start + 0.1, 1)), *anchored(self.anchor))


def one_policy(testcase_id: str, rng: random.Random, channel: str, action: ActionConfig, *, span: Span,
               description: str) -> TestCase:
    """A test case of one policy on ``channel`` over ``span``."""
    policy = Policy(id="p1", action=action, channels=(channel,), window=span.window(), selection=span.selection)
    return TestCase(id=testcase_id, seed=rng.getrandbits(32), description=description, policies=(policy,))


def set_testcase(testcase_id: str, rng: random.Random, channel: str, assignments: tuple[Assignment, ...], *,
                 span: Span, shape: str) -> TestCase:
    """A test case of one ``set`` policy on ``channel`` over ``span`` (``shape`` names it in the description)."""
    what = ", ".join(f"{a.path} = {a.value}" for a in assignments)
    return one_policy(testcase_id, rng, channel, Set(assignments), span=span,
                      description=describe(shape, channel, what, span, fields=len(assignments)))


def describe(shape: str, channel: str, what: str, span: Span, *, fields: int = 1) -> str:
    """``shape: channel: what`` and which messages (``span``'s): the one description format of every family."""
    window, selection = span.window(), span.selection
    if shape == "repeated":
        which = ("every message" if selection == Selection() else
                 f"every {ordinal(selection.every)} message" if selection.every != 1 else
                 f"messages with probability {selection.probability}")
        return f"repeated: {channel}: {what} on {which} from {window.start} s to {window.end} s"
    if shape in ("single", "multi_field"):
        count = "one field" if fields == 1 else f"{fields} fields"
        return f"{count} of one message: {channel}: {what}, first message after {window.start} s"
    if selection != Selection(limit=1):
        held_on = (f"every message from {window.start} s to {window.end} s" if selection.limit is None else
                   f"the {selection.limit} messages from {window.start} s")
        return f"{shape}: {channel}: {what} held on {held_on}"
    return f"{shape}: {channel}: {what}, first message after {window.start} s"


def ordinal(number: int) -> str:
    suffix = "th" if 10 <= number % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(number % 10, "th")
    return f"{number}{suffix}"


def anchored(anchor: str | None) -> tuple[str | None, int | None]:
    return (anchor, 1) if anchor is not None else (None, None)


def overlaps(a: FieldPath, b: FieldPath) -> bool:
    shorter, longer = sorted((a.segments, b.segments), key=len)
    return longer[:len(shorter)] == shorter


def disjoint_sample(rng: random.Random, targets: list[Target], wanted: int) -> list[Target]:
    """Up to ``wanted`` targets, none inside another (``points`` and ``points[*].v`` would collide)."""
    chosen: list[Target] = []
    for target in rng.sample(targets, len(targets)):
        if not any(overlaps(target.path, other.path) for other in chosen):
            chosen.append(target)
        if len(chosen) == wanted:
            break
    return sorted(chosen, key=targets.index)  # declaration order reads better


def drawn_values(rng: random.Random, chosen: Sequence[Target]) -> tuple[Assignment, ...]:
    """One dictionary value for each chosen target."""
    return tuple(Assignment(str(t.path), rng.choice(t.values).ref) for t in chosen)


# ---------------------------------------------------------------- semantic value families

PROBE_HELD_SHARE = 1 / 3  # semantic probes that hold their value instead of setting it on one message


class ValueFamily(FaultFamily):
    """A semantic family whose faults are dictionary values (``keys_of_kind``: per declared field kind,
    the entries in the order a coverage round tries them), on one message or held."""

    semantic = True
    keys_of_kind: ClassVar[dict[str, tuple[str, ...]]]

    def accepts(self, channel: Channel, path: FieldPath, field_type: FieldType) -> bool:
        """Whether this family acts on that field at all (default: every field of a listed kind)."""
        return True

    def targets(self, sources: Sources) -> Targets:
        return entry_targets(sources, dict(self.keys_of_kind), self.accepts)

    def draw(self, testcase_id: str, rng: random.Random, targets: Targets, scene: Scene) -> TestCase:
        channel = rng.choice(sorted(targets))
        target = rng.choice(targets[channel])
        entry = rng.choice(target.values)
        start = scene.start(rng)
        return self._testcase(testcase_id, rng, target, entry,
                              span=Span(start, *once_or_held(rng, start, scene.duration), scene.anchor))

    def probe(self, testcase_id: str, rng: random.Random, target: Target, *, visit: int, scene: Scene) -> TestCase:
        entry = target.values[visit % len(target.values)]  # the family's most telling value first
        start = scene.start(rng)
        until = held(rng, start, scene.duration) if rng.random() < PROBE_HELD_SHARE else (scene.duration,
                                                                                          Selection(limit=1))
        return self._testcase(testcase_id, rng, target, entry, span=Span(start, *until, scene.anchor))

    def _testcase(self, testcase_id: str, rng: random.Random, target: Target, entry: Entry, *, span: Span
                  ) -> TestCase:
        return set_testcase(testcase_id, rng, target.channel.name, (Assignment(str(target.path), entry.ref),),
                            span=span, shape=self.name)
