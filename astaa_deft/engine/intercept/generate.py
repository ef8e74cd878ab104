"""Generate ASTAA test cases from a SUT spec and the dictionary.

Each test case holds one policy on one channel (mostly ``set``), drawn from
the spec's channels, their leaf fields and the dictionary values of each
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

The families themselves are extensions (``astaa_deft/engine/intercept/faults/``,
one module each, in the ``FAMILIES`` registry): each says its weight, where
it can act, how it draws a case and describes it. This module is the
driver: it finds each family's targets once, draws a family by weight, and
runs the campaign's coverage rounds. Beyond the families above, the
*semantic* families draw plausible but wrong values (a bound hit exactly, an
angle a turn off, a unit mixed up, an array reordered, a field removed or
of another type, two siblings swapped, a stale copy; docs/policies.md).

Deterministic: the same spec, dictionary, count, seed, duration and
families give byte-identical files; with the families of an earlier release
(``families=``), the same files it gave.
"""

from __future__ import annotations

import random
from collections import Counter
from collections.abc import Collection, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from astaa_deft.io.codecs import get_codec
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.output_place import Place, ready_dir, write_atomic, writing
from astaa_deft.model.fields import leaf_fields
from astaa_deft.model.sut import Spec
from astaa_deft.engine.intercept.actions.set import Assignment
from astaa_deft.engine.intercept.dictionary import Dictionary, Entry, field_site, load_dictionary
from astaa_deft.engine.intercept.faults import FAMILIES, FaultFamily, Scene, Sources, Target, Targets, by_rank
from astaa_deft.engine.intercept.faults import owned_entries
from astaa_deft.engine.intercept.faults.base import (
    Span, held, is_generation_brittle, overlaps, set_testcase,
)
from astaa_deft.engine.intercept.faults.message import DELAYS_MS, MESSAGE_FAULTS, fault_testcase
from astaa_deft.engine.intercept.faults.stamp import (
    SEQUENCE_FAULTS, STAMP_FAULTS, STAMP_NAMES, stamp_targets, stamp_testcase,
)
from astaa_deft.engine.intercept.testcase import Selection, TestCase

__all__ = ["DELAYS_MS", "MESSAGE_FAULTS", "SEQUENCE_FAULTS", "STAMP_FAULTS", "STAMP_NAMES", "FaultTargets",
           "GenerateOptions", "GenerateReport", "Probe", "Target", "coverage_round", "fault_testcase", "generate",
           "generate_to_directory", "is_generation_brittle", "iter_testcases", "mutation_targets",
           "probe_testcase", "semantic_probe", "stamp_targets", "stamp_targets_by_channel", "targets_to_mutate",
           "value_class", "weighted_testcase", "write_testcases"]

# The families of the release before the semantic ones: ``families=EXCEPTIONAL`` draws what it drew.
EXCEPTIONAL = ("single", "multi_field", "repeated", "sustained", "stamp", "message")


@dataclass(frozen=True)
class FaultTargets:
    """Each family's targets by channel, found once for a spec and dictionary (families without a target
    left out)."""

    by_family: Mapping[str, Targets]
    cache: dict[str, object] = field(default_factory=dict, compare=False, repr=False)  # schedules built from it

    @classmethod
    def of(cls, spec: Spec, dictionary: Dictionary, include_brittle: bool = False,
           families: Collection[str] | None = None) -> FaultTargets:
        """InputError if the spec offers no field to mutate (for the exceptional-value families)."""
        sources = Sources(spec=spec, dictionary=dictionary, include_brittle=include_brittle,
                          exceptional=targets_to_mutate(spec, dictionary, include_brittle),
                          stamps=stamp_targets_by_channel(spec, dictionary))
        found = {family.name: family.targets(sources) for family in by_rank()
                 if families is None or family.name in families}
        return cls({name: targets for name, targets in found.items() if targets})

    @classmethod
    def exceptional(cls, by_channel: Targets, stamps: Targets | None = None) -> FaultTargets:
        """The families of ASTAA's shapes, sustained, message (and stamp, given ``stamps``) on given targets."""
        found = {name: by_channel for name in ("single", "multi_field", "repeated", "sustained", "message")}
        return cls({**found, **({"stamp": stamps} if stamps else {})})

    def families(self, *, message_faults: bool) -> list[FaultFamily]:
        """The families a weighted draw chooses from, in draw order."""
        return [family for family in by_rank()
                if family.name in self.by_family and (message_faults or not family.campaign_only)]

    def semantic(self) -> list[FaultFamily]:
        return [family for family in by_rank() if family.semantic and family.name in self.by_family]


def without_fields(targets: FaultTargets, fields: Collection[tuple[str, str]]) -> tuple[FaultTargets, int]:
    """``targets`` without the (channel, field path) in ``fields`` (array indices compared folded: ``points[*].x``
    is ``points[].x``), and how many targets went. A channel left without a target leaves the family; the
    message faults keep every channel (they change no field). Nothing is left out when no exceptional-value
    target would remain (a campaign needs something to mutate)."""
    import re

    def folded(path: str) -> str:
        return re.sub(r"\[[^\]]*\]", "[*]", path)

    gone = {(channel, folded(path)) for channel, path in fields}
    left = 0
    kept: dict[str, Targets] = {}
    for name, by_channel in targets.by_family.items():
        if FAMILIES[name].campaign_only:
            kept[name] = by_channel
            continue
        family: Targets = {}
        for channel, found in by_channel.items():
            stays = [t for t in found if (channel, folded(str(t.path))) not in gone]
            left += len(found) - len(stays)
            if stays:
                family[channel] = stays
        if family:
            kept[name] = family
    if "single" in targets.by_family and "single" not in kept:
        return targets, 0
    return FaultTargets(kept), left


def generate(spec: Spec, dictionary: Dictionary, count: int, seed: int, *, duration: float = 30.0,
             include_brittle: bool = False, families: Collection[str] | None = None) -> list[TestCase]:
    """``count`` test cases in a list (see :func:`iter_testcases`)."""
    return list(iter_testcases(spec, dictionary, count, seed, duration=duration, include_brittle=include_brittle,
                               families=families))


def iter_testcases(spec: Spec, dictionary: Dictionary, count: int, seed: int, *, duration: float = 30.0,
                   include_brittle: bool = False, families: Collection[str] | None = None) -> Iterator[TestCase]:
    """``count`` test cases, each drawn when the iterator reaches it (memory stays flat with the count).

    ``families``: the family names to draw from (None: every registered one).
    Raises ``InputError`` at once (not on the first draw) if the spec offers no field to mutate.
    """
    targets = FaultTargets.of(spec, dictionary, include_brittle, families)
    return (testcase for _family, testcase in _drawn(targets, count, seed, duration))


def targets_to_mutate(spec: Spec, dictionary: Dictionary, include_brittle: bool = False) -> dict[str, list[Target]]:
    """The exceptional-value targets by channel; InputError if the spec offers no field to mutate."""
    by_channel = _by_channel(mutation_targets(spec, dictionary, include_brittle))
    if not by_channel:
        raise InputError(Problem(str(spec.path or spec.name), None, None,
                                 "no field to mutate: every channel lacks consumers or non-brittle leaf fields",
                                 "use --include-brittle, or give channels consumers and typed fields"))
    return by_channel


def check_families(names: Iterable[str]) -> None:
    """InputError naming an unknown family (``--family``)."""
    for name in names:
        if name not in FAMILIES:
            raise InputError(Problem("--family", None, None, f"unknown fault family {name!r}",
                                     "families are " + ", ".join(FAMILIES.names())))


def _drawn(targets: FaultTargets, count: int, seed: int, duration: float) -> Iterator[tuple[str, TestCase]]:
    """(family, test case) for each of ``count`` cases, drawn one at a time."""
    width = _id_width(count)
    scene = Scene(duration)
    for number in range(1, count + 1):
        yield _draw(_testcase_id(number, width), random.Random(f"{seed}/{number}"), targets, scene)


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
    shapes: Counter[str]  # test cases per family (single, multi_field, …, boundary, angle, …)

    @property
    def paths(self) -> list[Path]:
        """The test case files written, in order."""
        width = _id_width(self.count)
        return [self.directory / f"{_testcase_id(number, width)}.xml" for number in range(1, self.count + 1)]


@dataclass(frozen=True, kw_only=True)
class GenerateOptions:
    """What ``generate`` draws: how many test cases from which seed, their windows within ``duration`` seconds,
    on which fields (``include_brittle``: timestamps and sequence numbers too), with which dictionaries on top
    of the bundled one, of which fault families (None: every family but the campaign's message faults)."""

    count: int
    seed: int
    duration: float = 30.0
    include_brittle: bool = False
    dictionaries: Sequence[Path] = ()
    families: Collection[str] | None = None


def generate_to_directory(spec: Spec, out_dir: Path, options: GenerateOptions) -> GenerateReport:
    """Write ``options.count`` test cases drawn from ``spec`` and the dictionaries into a new or empty
    ``out_dir``.

    InputError for a bad count or duration, an unknown family, an output
    directory holding test cases already, or a dictionary that does not load;
    OutputError (checked before drawing) when ``out_dir`` cannot take files,
    or when a write fails.
    """
    count, seed, duration, families = options.count, options.seed, options.duration, options.families
    if count < 1:
        raise InputError(Problem("--count", None, None, f"{count} test cases", "ask for at least 1"))
    if not duration > 0:
        raise InputError(Problem("--duration", None, None, f"{duration} s", "give a positive number of seconds"))
    if families is not None:
        check_families(families)
    _check_output_directory(out_dir)
    place = Place(out_dir, "-o")
    ready_dir(place)
    dictionary = load_dictionary(options.dictionaries)
    drawn = _drawn(FaultTargets.of(spec, dictionary, options.include_brittle, families), count, seed, duration)
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
    """Every (channel, leaf field) with at least one usable exceptional value, in spec order (entries a
    family owns, ``FaultFamily.owns``, left out)."""
    owned = owned_entries()
    targets = []
    for channel in spec.channels:
        if not channel.consumers:  # nobody would receive the mutation
            continue
        codec = get_codec(channel.encoding)
        for path, _field_type in leaf_fields(spec.types, channel.type):
            if not include_brittle and is_generation_brittle(spec, channel.type, path):
                continue
            site = field_site(spec.types, channel.type, path)
            usable, _skipped = dictionary.usable(site, codec,
                                                 [e for e in dictionary.entries_for(site) if e.key not in owned])
            if usable:
                targets.append(Target(channel=channel, path=path, site=site, values=tuple(usable)))
    return targets


def _by_channel(targets: Sequence[Target]) -> dict[str, list[Target]]:
    grouped: dict[str, list[Target]] = {}
    for target in targets:
        grouped.setdefault(target.channel.name, []).append(target)
    return grouped


def stamp_targets_by_channel(spec: Spec, dictionary: Dictionary) -> dict[str, list[Target]]:
    return _by_channel(stamp_targets(spec, dictionary))


# ---------------------------------------------------------------- drawing one test case

def weighted_testcase(testcase_id: str, rng: random.Random, targets: FaultTargets | Targets, duration: float, *,
                      anchor: str | None = None, message_faults: bool = False,
                      stamps: Targets | None = None) -> TestCase:
    """One weighted draw (:func:`_draw`) without its family's name.

    ``targets``: every family's (:class:`FaultTargets`), or the exceptional
    targets by channel alone (then ASTAA's shapes and sustained, plus the
    stamp family given ``stamps``, and the message family given ``message_faults``).
    """
    if not isinstance(targets, FaultTargets):
        targets = FaultTargets.exceptional(targets, stamps)
    return _draw(testcase_id, rng, targets, Scene(duration, anchor), message_faults=message_faults)[1]


def _draw(testcase_id: str, rng: random.Random, targets: FaultTargets, scene: Scene, *,
          message_faults: bool = False) -> tuple[str, TestCase]:
    """A family drawn by weight, then its case; (family, test case). ``message_faults``: campaign-only
    families (message faults) take part."""
    families = targets.families(message_faults=message_faults)
    family = rng.choices(families, weights=[f.weight for f in families])[0]
    return family.name, family.draw(testcase_id, rng, dict(targets.by_family[family.name]), scene)


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
# The semantic families have a schedule of their own (:func:`semantic_probe`):
# the families take turns, each walking its targets lap by lap, its k-th value in lap k.

MESSAGE_FAULT_WEIGHT = FAMILIES["message"].weight
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
    """One case of a coverage round: a field with a value of the round's class, a message fault,
    (``fault`` = ``STAMP_PROBE``) a stamp or sequence field with the round's stamp fault, or (``family``)
    a target of a semantic family."""

    channel: str
    target: Target | None  # None: a message fault
    fault: str | None = None
    family: str | None = None


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
    return _interleaved(per_channel)


def _interleaved(lanes: list[list[Probe]]) -> list[Probe]:
    """The lanes' first probes, then their second ones, …"""
    ordered: list[Probe] = []
    for turn in range(max((len(p) for p in lanes), default=0)):
        ordered.extend(p[turn] for p in lanes if turn < len(p))
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


def semantic_probe(targets: FaultTargets, seed: int, number: int) -> tuple[Probe, int] | None:
    """The ``number``-th (from 0) probe of the semantic families and its lap; None if none has a target.

    The families take turns, each walking its own targets: a family's k-th
    probe visits its targets in a seeded order, one lap after another, and
    lap L gives each target its family's L-th value (the most telling first).
    A family whose every target has had every value (``FaultFamily.visits``)
    leaves the turns to the others until all have; then it starts again. So
    a family with one target tries its next value every few probes, and a
    family with many targets is not slowed by one that has nothing new.
    """
    order, totals = _semantic_pass(targets)
    if not order:
        return None
    passes, position = divmod(number, len(order))
    name, k = order[position]
    family = FAMILIES[name]
    own = [(channel, target) for channel in sorted(targets.by_family[name])
           for target in targets.by_family[name][channel]]
    lap, index = divmod(passes * totals[name] + k, len(own))
    channel, target = random.Random(f"semantic/{seed}/{family.name}/{lap}").sample(own, len(own))[index]
    return Probe(channel, target, family=name), lap


def _semantic_pass(targets: FaultTargets) -> tuple[list[tuple[str, int]], dict[str, int]]:
    """One pass of the semantic schedule: (family, its probe number) in turn order, and each family's probes
    in a pass (laps until its every target had every value)."""
    cached = targets.cache.get("semantic_pass")
    if cached is None:
        families = targets.semantic()
        totals = {}
        for family in families:
            own = [t for channel_targets in targets.by_family[family.name].values() for t in channel_targets]
            totals[family.name] = len(own) * max(family.visits(t) for t in own)
        order = [(family.name, turn) for turn in range(max(totals.values(), default=0))
                 for family in families if turn < totals[family.name]]
        cached = targets.cache["semantic_pass"] = (order, totals)
    return cached  # type: ignore[return-value]


def probe_testcase(testcase_id: str, rng: random.Random, probe: Probe, round_number: int, *, duration: float,
                   anchor: str | None = None) -> TestCase:
    """The test case of one probe: one message (or a held value), at a random time inside ``duration``."""
    # Early rounds ask "does this value break the field's consumers at all?": early windows answer that
    # in shorter runs; later rounds spread over the whole live run for state-dependent failures.
    latest = duration * 0.8 * min(1.0, (round_number + 1) / SPREAD_ROUNDS)
    scene = Scene(duration, anchor, latest)
    if probe.family is not None:
        assert probe.target is not None
        return FAMILIES[probe.family].probe(testcase_id, rng, probe.target, visit=round_number, scene=scene)
    if probe.target is None:
        return fault_testcase(testcase_id, rng, probe.channel, probe.fault or MESSAGE_FAULTS[0], scene=scene,
                              repeated=False)
    if probe.fault == STAMP_PROBE:  # the round's stamp fault, NaN first (the field's own when it cannot take it)
        wanted = STAMP_FAULTS[round_number % len(STAMP_FAULTS)]
        fault = next((e for e in probe.target.values if e.key == wanted),
                     probe.target.values[round_number % len(probe.target.values)])
        return stamp_testcase(testcase_id, rng, probe.target, fault, scene=scene)
    entry = value_for_round(probe.target, round_number, rng)
    assignments = (Assignment(str(probe.target.path), entry.ref),)
    start = scene.start(rng)
    if rng.random() < SUSTAINED_PROBE_SHARE:
        return set_testcase(testcase_id, rng, probe.channel, assignments,
                            span=Span(start, *held(rng, start, duration), anchor), shape="sustained")
    return set_testcase(testcase_id, rng, probe.channel, assignments,
                        span=Span(start, duration, Selection(limit=1), anchor), shape="single")


_overlaps = overlaps  # the campaign's guided strategy checks multi-field cases with it
