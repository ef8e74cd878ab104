"""Generate ASTAA test cases from a SUT spec and the dictionary.

Each test case holds one ``set`` policy on one channel, drawn from the
spec's channels, their leaf fields and the dictionary values of each
field's declared type. The mix follows what ASTAA's bugs needed
(Hutchison et al., ICSE-SEIP 2018, Fig. 3): 42 % one bad value in one
field of one message, 22 % several fields of one message, only 8 %
repeated injection. Normalised over those 72 %, about 58 % of test cases
mutate one field of one message, 31 % several fields of one message and
11 % one field over many messages. Two families come on top of ASTAA's
shapes, for faults a real stack needs (docs/policies.md): *sustained*
cases hold one bad value on every message of a 1–5 s window or on the next
5–50 messages (a stack that ignores one bad message may not ignore it held),
and *stamp* cases put a NaN, backwards, far-future or repeated value into a
stamp or sequence number, brittle or not (a small share: such faults mostly
test bookkeeping, but a NaN stamp can stop a planner).

Windows are random inside the scenario's duration (rounded to 0.1 s so
the files read well). Brittle fields (the spec's list, plus stamps and
sequence numbers in header-like structs) are left alone unless asked (the
stamp family excepted): mutating them mostly tests the middleware's
bookkeeping, not the robot.

Deterministic: the same spec, dictionary, count, seed and duration give
byte-identical files.
"""

from __future__ import annotations

import random
from collections import Counter
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from astaa_deft.io.codecs import get_codec
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.output_place import Place, ready_dir, write_atomic, writing
from astaa_deft.model.fields import FieldPath, is_brittle, leaf_fields, type_at
from astaa_deft.model.sut import INT_KINDS, Channel, Spec
from astaa_deft.engine.intercept.actions.base import ActionConfig
from astaa_deft.engine.intercept.actions.delay import Delay
from astaa_deft.engine.intercept.actions.drop import Drop
from astaa_deft.engine.intercept.actions.duplicate import Duplicate
from astaa_deft.engine.intercept.actions.reorder import Reorder
from astaa_deft.engine.intercept.actions.set import Assignment, Set
from astaa_deft.engine.intercept.dictionary import Dictionary, Entry, FieldSite, field_site, load_dictionary
from astaa_deft.engine.intercept.testcase import Policy, Selection, TestCase, Window

# (shape, weight in % of the bugs ASTAA found that needed it)
SHAPES = (("single", 42), ("multi_field", 22), ("repeated", 8))
# Families beyond ASTAA's shapes, weighted next to SHAPES' 72: of generate's cases about 20 % sustained and
# 7 % stamp faults (17 % and 6 % when a campaign adds its message faults).
SUSTAINED_WEIGHT = 20
STAMP_WEIGHT = 7
SUSTAINED_SECONDS = (1.0, 5.0)  # a held value: every message of a window this long …
SUSTAINED_MESSAGES = (5, 50)  # … or this many messages in a row
# Stamp and sequence fields, found by name anywhere in a message (brittle or not), and their faults: a
# stamp (any non-integer field) gets NaN, a jump back (previous stamp - 1 s), the far future or the previous
# stamp again; an integer (a sequence number, a stamp's seconds) the previous value again (a duplicate seq).
# A fault the field's codec cannot carry is left out for that field.
STAMP_NAMES = frozenset({"stamp", "timestamp", "seq", "sequence"})
STAMP_FAULTS = ("time.nan", "time.jump_back", "time.far_future", "time.repeat_previous")
SEQUENCE_FAULTS = ("time.repeat_previous",)
# Field names that are bookkeeping when they sit in a header-like struct.
HEADER_BOOKKEEPING = frozenset({"stamp", "timestamp", "seq", "sequence", "frame_id"})
MAX_FIELDS_PER_MESSAGE = 4


@dataclass(frozen=True)
class Target:
    """A field generation may mutate, with the dictionary values its channel can carry."""

    channel: Channel
    path: FieldPath
    site: FieldSite
    values: tuple[Entry, ...]


def generate(spec: Spec, dictionary: Dictionary, count: int, seed: int, duration: float = 30.0,
             include_brittle: bool = False) -> list[TestCase]:
    """``count`` test cases in a list (see :func:`iter_testcases`)."""
    return list(iter_testcases(spec, dictionary, count, seed, duration, include_brittle))


def iter_testcases(spec: Spec, dictionary: Dictionary, count: int, seed: int, duration: float = 30.0,
                   include_brittle: bool = False) -> Iterator[TestCase]:
    """``count`` test cases, each drawn when the iterator reaches it (memory stays flat with the count).

    Raises ``InputError`` at once (not on the first draw) if the spec offers no field to mutate.
    """
    by_channel = targets_to_mutate(spec, dictionary, include_brittle)
    return (testcase for _shape, testcase in _drawn(spec, dictionary, by_channel, count, seed, duration))


def targets_to_mutate(spec: Spec, dictionary: Dictionary, include_brittle: bool = False) -> dict[str, list[Target]]:
    """The bulk's targets by channel; InputError if the spec offers no field to mutate."""
    by_channel = _targets_by_channel(spec, dictionary, include_brittle)
    if not by_channel:
        raise InputError(Problem(str(spec.path or spec.name), None, None,
                                 "no field to mutate: every channel lacks consumers or non-brittle leaf fields",
                                 "use --include-brittle, or give channels consumers and typed fields"))
    return by_channel


def _drawn(spec: Spec, dictionary: Dictionary, by_channel: dict[str, list[Target]], count: int, seed: int,
           duration: float) -> Iterator[tuple[str, TestCase]]:
    """(family, test case) for each of ``count`` cases, drawn one at a time."""
    stamps = stamp_targets_by_channel(spec, dictionary)
    width = _id_width(count)
    for number in range(1, count + 1):
        yield _draw(_testcase_id(number, width), random.Random(f"{seed}/{number}"), by_channel, duration,
                    stamps=stamps)


def _id_width(count: int) -> int:
    return max(4, len(str(count)))


def _testcase_id(number: int, width: int) -> str:
    return f"tc-{number:0{width}d}"


def write_testcases(testcases: Iterable[TestCase], directory: Path) -> list[Path]:
    directory.mkdir(parents=True, exist_ok=True)
    return [_write_testcase(testcase, directory) for testcase in testcases]


def _write_testcase(testcase: TestCase, directory: Path) -> Path:
    """``directory/<id>.xml``, whole or absent (OSError propagates)."""
    path = directory / f"{testcase.id}.xml"
    write_atomic(path, testcase.to_xml())
    return path


# ---------------------------------------------------------------- the workflow behind `astaa-deft generate`

@dataclass(frozen=True)
class GenerateReport:
    directory: Path
    count: int  # test case files written
    shapes: Counter[str]  # test cases per family: single, multi_field, repeated, sustained, stamp

    @property
    def paths(self) -> list[Path]:
        """The test case files written, in order."""
        width = _id_width(self.count)
        return [self.directory / f"{_testcase_id(number, width)}.xml" for number in range(1, self.count + 1)]


def generate_to_directory(spec: Spec, count: int, seed: int, out_dir: Path, duration: float = 30.0,
                          include_brittle: bool = False, dictionaries: Sequence[Path] = ()) -> GenerateReport:
    """Write ``count`` test cases drawn from ``spec`` and the dictionaries into a new or empty ``out_dir``.

    InputError for a bad count or duration, an output directory holding test
    cases already, or a dictionary that does not load; OutputError (checked
    before drawing) when ``out_dir`` cannot take files, or when a write fails.
    """
    if count < 1:
        raise InputError(Problem("--count", None, None, f"{count} test cases", "ask for at least 1"))
    if not duration > 0:
        raise InputError(Problem("--duration", None, None, f"{duration} s", "give a positive number of seconds"))
    _check_output_directory(out_dir)
    place = Place(out_dir, "-o")
    ready_dir(place)
    dictionary = load_dictionary(dictionaries)
    drawn = _drawn(spec, dictionary, targets_to_mutate(spec, dictionary, include_brittle), count, seed, duration)
    shapes: Counter[str] = Counter()
    with writing(place):
        out_dir.mkdir(parents=True, exist_ok=True)
        for shape, testcase in drawn:  # each written as drawn: nothing of the whole set is held
            _write_testcase(testcase, out_dir)
            shapes[shape] += 1
    return GenerateReport(out_dir, count, shapes)


def _check_output_directory(out_dir: Path) -> None:
    """Refuse to mix with earlier test cases: a stale tc-0042.xml would be run as if it were new."""
    existing = sorted(out_dir.glob("tc-*.xml")) if out_dir.is_dir() else []
    if existing:
        raise InputError(Problem(str(out_dir), None, None,
                                 f"already holds {len(existing)} test case file(s), e.g. {existing[0].name}",
                                 "give a new or empty directory with -o, or delete them"))


# ---------------------------------------------------------------- what may be mutated

def mutation_targets(spec: Spec, dictionary: Dictionary, include_brittle: bool = False) -> list[Target]:
    """Every (channel, leaf field) with at least one usable dictionary value, in spec order."""
    targets = []
    for channel in spec.channels:
        if not channel.consumers:  # nobody would receive the mutation
            continue
        codec = get_codec(channel.encoding)
        for path, _field_type in leaf_fields(spec.types, channel.type):
            if not include_brittle and is_generation_brittle(spec, channel.type, path):
                continue
            site = field_site(spec.types, channel.type, path)
            usable, _skipped = dictionary.usable(site, codec)
            if usable:
                targets.append(Target(channel, path, site, tuple(usable)))
    return targets


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


def _targets_by_channel(spec: Spec, dictionary: Dictionary, include_brittle: bool) -> dict[str, list[Target]]:
    return _by_channel(mutation_targets(spec, dictionary, include_brittle))


def _by_channel(targets: Sequence[Target]) -> dict[str, list[Target]]:
    grouped: dict[str, list[Target]] = {}
    for target in targets:
        grouped.setdefault(target.channel.name, []).append(target)
    return grouped


def stamp_targets(spec: Spec, dictionary: Dictionary) -> list[Target]:
    """Every stamp or sequence field (a name in ``STAMP_NAMES`` on its path, brittle or not) of a channel with
    consumers, with the faults it can take (``STAMP_FAULTS``, or ``SEQUENCE_FAULTS`` for integers); per
    channel the stamps first, then the integers, each in spec order. Faults missing from the dictionary
    (a user's file removed them) are left out."""
    stamp_faults = [dictionary.get(key) for key in STAMP_FAULTS if key in dictionary]
    sequence_faults = [dictionary.get(key) for key in SEQUENCE_FAULTS if key in dictionary]
    targets = []
    for channel in spec.channels:
        if not channel.consumers:
            continue
        codec = get_codec(channel.encoding)
        found: list[Target] = []
        for path, field_type in leaf_fields(spec.types, channel.type):
            if not any(type(s) is str and s.lower() in STAMP_NAMES for s in path.segments):
                continue
            site = field_site(spec.types, channel.type, path)
            faults = sequence_faults if field_type.kind in INT_KINDS else stamp_faults
            usable, _skipped = dictionary.usable(site, codec, faults)
            if usable:
                found.append(Target(channel, path, site, tuple(usable)))
        targets.extend(sorted(found, key=lambda t: t.site.field_type.kind in INT_KINDS))  # stable: spec order
    return targets


def stamp_targets_by_channel(spec: Spec, dictionary: Dictionary) -> dict[str, list[Target]]:
    return _by_channel(stamp_targets(spec, dictionary))


# ---------------------------------------------------------------- drawing one test case

def weighted_testcase(testcase_id: str, rng: random.Random, by_channel: dict[str, list[Target]],
                      duration: float, anchor: str | None = None, *, message_faults: bool = False,
                      stamps: dict[str, list[Target]] | None = None) -> TestCase:
    """One weighted draw (:func:`_draw`) without its shape's name."""
    return _draw(testcase_id, rng, by_channel, duration, anchor, message_faults=message_faults, stamps=stamps)[1]


def _draw(testcase_id: str, rng: random.Random, by_channel: dict[str, list[Target]], duration: float,
          anchor: str | None = None, *, message_faults: bool = False,
          stamps: dict[str, list[Target]] | None = None) -> tuple[str, TestCase]:
    """ASTAA's weighted draw plus the sustained family and (given ``stamps``, the stamp targets by channel)
    the stamp family; returns (shape, test case). ``anchor``: windows count from that channel's first
    message; ``message_faults``: a share of cases reorder, delay, duplicate or drop messages instead."""
    shapes = SHAPES + (("sustained", SUSTAINED_WEIGHT),) + ((("stamp", STAMP_WEIGHT),) if stamps else ()) \
        + ((("message", MESSAGE_FAULT_WEIGHT),) if message_faults else ())
    shape = rng.choices([name for name, _ in shapes], weights=[weight for _, weight in shapes])[0]
    if shape == "message":
        channel = rng.choice(sorted(by_channel))
        return shape, fault_testcase(testcase_id, rng, channel, rng.choice(MESSAGE_FAULTS), duration=duration,
                                     anchor=anchor)
    if shape == "stamp":
        assert stamps
        channel = rng.choice(sorted(stamps))
        target = rng.choice(stamps[channel])
        return shape, stamp_testcase(testcase_id, rng, target, rng.choice(target.values), duration, anchor)
    channel = rng.choice(sorted(by_channel))  # channels equally likely, whatever their field count
    targets = by_channel[channel]
    if shape == "multi_field":
        chosen = _disjoint_sample(rng, targets, rng.randint(2, MAX_FIELDS_PER_MESSAGE))
    else:
        chosen = [rng.choice(targets)]
    assignments = tuple(Assignment(str(t.path), rng.choice(t.values).ref) for t in chosen)
    start = round(rng.uniform(0.0, duration * 0.8), 1)
    if shape == "sustained":
        return shape, _one_policy(testcase_id, rng, channel, assignments,
                                  span=_Span(start, *_held(rng, start, duration), anchor), shape="sustained")
    if shape == "repeated":
        end = min(round(start + rng.uniform(1.0, 5.0), 1), duration)
        selection = rng.choice([Selection(), Selection(every=rng.choice([2, 5, 10])),
                                Selection(probability=rng.choice([0.1, 0.25, 0.5]))])
    else:  # one message: the first one in the window
        end = duration
        selection = Selection(limit=1)
    return shape, _one_policy(testcase_id, rng, channel, assignments, span=_Span(start, end, selection, anchor),
                              shape=shape)


def _held(rng: random.Random, start: float, duration: float) -> tuple[float, Selection]:
    """Where a held value's window ends and what it selects: every message of a 1–5 s window, or the
    next 5–50 messages (the window stays open until ``duration``; the limit ends it)."""
    if rng.random() < 0.5:
        return min(round(start + rng.uniform(*SUSTAINED_SECONDS), 1), duration), Selection()
    return duration, Selection(limit=rng.randint(*SUSTAINED_MESSAGES))


@dataclass(frozen=True)
class _Span:
    """A policy's window from ``start`` s to ``end`` s (at least 0.1 s), selecting ``selection``; its times
    count from ``anchor``'s first message (None: from the run's start)."""

    start: float
    end: float
    selection: Selection
    anchor: str | None


def _one_policy(testcase_id: str, rng: random.Random, channel: str, assignments: tuple[Assignment, ...], *,
                span: _Span, shape: str) -> TestCase:
    """A test case of one ``set`` policy on ``channel`` over ``span`` (``shape`` names it in the description)."""
    window = Window(span.start, max(span.end, round(span.start + 0.1, 1)), *_anchored(span.anchor))
    policy = Policy("p1", Set(assignments), channels=(channel,), window=window, selection=span.selection)
    return TestCase(testcase_id, rng.getrandbits(32),
                    _describe(shape, channel, assignments, window, span.selection), (policy,))


def stamp_testcase(testcase_id: str, rng: random.Random, target: Target, fault: Entry, duration: float,
                   anchor: str | None = None, latest: float | None = None) -> TestCase:
    """A stamp or sequence fault on one field: on one message, or (by chance, half of them) held;
    starting by ``latest`` s (default: 80 % of ``duration``)."""
    start = round(rng.uniform(0.0, duration * 0.8 if latest is None else latest), 1)
    until = _held(rng, start, duration) if rng.random() < 0.5 else (duration, Selection(limit=1))
    return _one_policy(testcase_id, rng, target.channel.name, (Assignment(str(target.path), fault.ref),),
                       span=_Span(start, *until, anchor), shape="stamp")


def _disjoint_sample(rng: random.Random, targets: list[Target], wanted: int) -> list[Target]:
    """Up to ``wanted`` targets, none inside another (``points`` and ``points[*].v`` would collide)."""
    chosen: list[Target] = []
    for target in rng.sample(targets, len(targets)):
        if not any(_overlaps(target.path, other.path) for other in chosen):
            chosen.append(target)
        if len(chosen) == wanted:
            break
    return sorted(chosen, key=targets.index)  # declaration order reads better


def _overlaps(a: FieldPath, b: FieldPath) -> bool:
    shorter, longer = sorted((a.segments, b.segments), key=len)
    return longer[:len(shorter)] == shorter


def _describe(shape: str, channel: str, assignments: Sequence[Assignment], window: Window,
              selection: Selection) -> str:
    values = ", ".join(f"{a.path} = {a.value}" for a in assignments)
    if shape in ("sustained", "stamp") and selection != Selection(limit=1):
        held = (f"every message from {window.start} s to {window.end} s" if selection.limit is None else
                f"the {selection.limit} messages from {window.start} s")
        return f"{shape}: {channel}: {values} held on {held}"
    if shape == "stamp":
        return f"stamp: {channel}: {values}, first message after {window.start} s"
    if shape == "repeated":
        which = ("every message" if selection == Selection() else
                 f"every {_ordinal(selection.every)} message" if selection.every != 1 else
                 f"messages with probability {selection.probability}")
        return f"repeated: {channel}: {values} on {which} from {window.start} s to {window.end} s"
    fields = "one field" if len(assignments) == 1 else f"{len(assignments)} fields"
    return f"{fields} of one message: {channel}: {values}, first message after {window.start} s"


def _ordinal(number: int) -> str:
    suffix = "th" if 10 <= number % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(number % 10, "th")
    return f"{number}{suffix}"


# ---------------------------------------------------------------- coverage-first probes (campaigns)
#
# A campaign has a budget of a few hundred runs, not ASTAA's thousands: it
# should try every channel and field early, with the values most likely to
# break something first, instead of drawing the same field again before
# another was ever touched. A *round* visits every (channel, field) once and
# applies one message fault (no field changed) to every channel; round k
# gives each field a value of its k-th value class, so round 0 tries the
# non-finite (or empty) values everywhere, round 1 the extreme magnitudes, …
# A third of the field probes hold their value (sustained); a round also
# puts the round's stamp fault (NaN first) into a stamp or sequence field of
# a few channels, about STAMP_SHARE of the round, the channels taking turns.

# Message faults: timing and ordering bugs need no bad value (a stamp going
# backwards after a reorder, a late message overtaken by newer ones).
MESSAGE_FAULTS = ("reorder", "delay", "duplicate", "drop")
MESSAGE_FAULT_WEIGHT = 14  # % of weighted cases, next to SHAPES' 72: ASTAA's remaining bug classes were timing
DELAYS_MS = (50, 100, 200, 500)
# Value classes in the order a round uses them: what breaks code most often first (Ballista, ASTAA).
VALUE_CLASSES = ("non_finite", "empty", "extreme", "null", "bound", "zero", "tiny", "other")
SPREAD_ROUNDS = 3  # round r's windows open in the first (r + 1) / 3 of the live run's 80 %
EXTREME = 1e15  # magnitudes where float arithmetic stops behaving (2**53 ≈ 9e15: integers skip)
SUSTAINED_PROBE_SHARE = 1 / 3  # field probes that hold their value instead of setting it on one message
STAMP_SHARE = 0.07  # of a round: stamp and sequence probes (at least one, at most one per channel)
STAMP_PROBE = "stamp"  # Probe.fault of a stamp probe


def value_class(entry: Entry) -> str:
    """The class of a dictionary entry, from its value or derive rule (not its name)."""
    if entry.rule is not None:
        rule = entry.rule
        if rule in ("below_min", "above_max"):
            return "bound"
        if rule.startswith("width_"):
            return "extreme"
        return "other"
    value = entry.value
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "other"
    if isinstance(value, float) and value != value or isinstance(value, float) and abs(value) == float("inf"):
        return "non_finite"
    if isinstance(value, (int, float)):
        magnitude = abs(value)
        if magnitude >= EXTREME:
            return "extreme"
        if magnitude in (0, 1):
            return "zero"
        return "tiny" if magnitude < 1e-30 else "other"
    if isinstance(value, (str, bytes, list, dict, tuple)):
        if len(value) == 0:
            return "empty"
        return "extreme" if len(value) >= 1024 else "other"
    return "other"


def value_for_round(target: Target, round_number: int, rng: random.Random) -> Entry:
    """A value of the target's ``round_number``-th class present (cycling), drawn with ``rng``."""
    classes: dict[str, list[Entry]] = {}
    for entry in target.values:
        classes.setdefault(value_class(entry), []).append(entry)
    ordered = [classes[name] for name in VALUE_CLASSES if name in classes]
    return rng.choice(ordered[round_number % len(ordered)])


@dataclass(frozen=True)
class Probe:
    """One case of a coverage round: a field with a value of the round's class, a message fault, or
    (``fault`` = ``STAMP_PROBE``) a stamp or sequence field with the round's stamp fault."""

    channel: str
    target: Target | None  # None: a message fault
    fault: str | None = None


def coverage_round(by_channel: dict[str, list[Target]], seed: int, round_number: int,
                   stamps: dict[str, list[Target]] | None = None) -> list[Probe]:
    """Every (channel, field) once, one message fault per channel and a few stamp probes; channels interleaved.

    Channels take turns (in a seeded order), so the first cases of a round
    touch every channel before any channel's second field. ``stamps`` (the
    stamp targets by channel): about ``STAMP_SHARE`` of the round are stamp
    probes, one per channel, the channels taking turns from round to round.
    """
    rng = random.Random(f"coverage/{seed}/{round_number}")
    per_channel: list[list[Probe]] = []
    for channel in rng.sample(sorted(by_channel), len(by_channel)):
        probes = [Probe(channel, target) for target in by_channel[channel]]
        rng.shuffle(probes)
        fault = MESSAGE_FAULTS[round_number % len(MESSAGE_FAULTS)]
        probes.insert(rng.randrange(min(len(probes), 2) + 1), Probe(channel, None, fault))
        per_channel.append(probes)
    if stamps:
        per_channel.append(_stamp_probes(stamps, round_number, sum(len(p) for p in per_channel)))
    ordered: list[Probe] = []
    for turn in range(max(len(p) for p in per_channel)):
        ordered.extend(p[turn] for p in per_channel if turn < len(p))
    return ordered


def _stamp_probes(stamps: dict[str, list[Target]], round_number: int, round_length: int) -> list[Probe]:
    """Round ``round_number``'s stamp probes: ``STAMP_SHARE`` of a round of ``round_length`` other probes
    (at least one), on channels taken in turn; each channel's fields in turn too."""
    channels = sorted(stamps)
    wanted = min(len(channels), max(1, round(STAMP_SHARE * round_length)))
    probes = []
    for k in range(wanted):
        turn = round_number * wanted + k
        channel = channels[turn % len(channels)]
        fields = stamps[channel]
        probes.append(Probe(channel, fields[(turn // len(channels)) % len(fields)], STAMP_PROBE))
    return probes


def probe_testcase(testcase_id: str, rng: random.Random, probe: Probe, round_number: int, duration: float,
                   anchor: str | None = None) -> TestCase:
    """The test case of one probe: one message, at a random time inside ``duration``."""
    # Early rounds ask "does this value break the field's consumers at all?": early windows answer that
    # in shorter runs; later rounds spread over the whole live run for state-dependent failures.
    latest = duration * 0.8 * min(1.0, (round_number + 1) / SPREAD_ROUNDS)
    if probe.target is None:
        return fault_testcase(testcase_id, rng, probe.channel, probe.fault or MESSAGE_FAULTS[0], duration=duration,
                              anchor=anchor, repeated=False, latest=latest)
    if probe.fault == STAMP_PROBE:  # the round's stamp fault, NaN first (the field's own when it cannot take it)
        wanted = STAMP_FAULTS[round_number % len(STAMP_FAULTS)]
        fault = next((e for e in probe.target.values if e.key == wanted),
                     probe.target.values[round_number % len(probe.target.values)])
        return stamp_testcase(testcase_id, rng, probe.target, fault, duration, anchor, latest=latest)
    entry = value_for_round(probe.target, round_number, rng)
    assignments = (Assignment(str(probe.target.path), entry.ref),)
    start = round(rng.uniform(0.0, latest), 1)
    if rng.random() < SUSTAINED_PROBE_SHARE:
        return _one_policy(testcase_id, rng, probe.channel, assignments,
                           span=_Span(start, *_held(rng, start, duration), anchor), shape="sustained")
    return _one_policy(testcase_id, rng, probe.channel, assignments,
                       span=_Span(start, duration, Selection(limit=1), anchor), shape="single")


def fault_testcase(testcase_id: str, rng: random.Random, channel: str, fault: str, *, duration: float,
                   anchor: str | None = None, repeated: bool | None = None, latest: float | None = None) -> TestCase:
    """One message fault on ``channel``: one message, or (``repeated``, else by chance) a burst;
    starting by ``latest`` s (default: 80 % of ``duration``)."""
    action: ActionConfig = {"reorder": Reorder(), "delay": Delay(float(rng.choice(DELAYS_MS))), "drop": Drop(),
                            "duplicate": Duplicate()}[fault]
    start = round(rng.uniform(0.0, duration * 0.8 if latest is None else latest), 1)
    if repeated is None:
        repeated = rng.random() < 0.5
    if repeated:
        end = min(round(start + rng.uniform(0.5, 3.0), 1), duration)
        selection = Selection(every=rng.choice([1, 2, 5]))
        which = "every message" if selection.every == 1 else f"every {_ordinal(selection.every)} message"
        what = f"{which} from {start} s to {end} s"
    else:
        end, selection = duration, Selection(limit=1)
        what = f"first message after {start} s"
    window = Window(start, max(end, round(start + 0.1, 1)), *_anchored(anchor))
    policy = Policy("p1", action, channels=(channel,), window=window, selection=selection)
    return TestCase(testcase_id, rng.getrandbits(32), f"{fault}: {channel}: {what}"
                    + (f" (counted from the first {anchor} message)" if anchor else ""), (policy,))


def _anchored(anchor: str | None) -> tuple[str | None, int | None]:
    return (anchor, 1) if anchor is not None else (None, None)
