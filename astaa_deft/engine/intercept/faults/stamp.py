"""``stamp``: a NaN, backwards, far-future or repeated value in a stamp or sequence number, brittle or
not, on one message or held (a small share: such faults mostly test bookkeeping, but a NaN stamp can stop
a planner)."""

from __future__ import annotations

import random

from astaa_deft.io.codecs import get_codec
from astaa_deft.model.fields import leaf_fields
from astaa_deft.model.sut import INT_KINDS
from astaa_deft.engine.intercept.actions.set import Assignment
from astaa_deft.engine.intercept.dictionary import Dictionary, Entry, field_site
from astaa_deft.engine.intercept.faults import FAMILIES
from astaa_deft.engine.intercept.faults.base import (
    FaultFamily, Scene, Sources, Span, Target, Targets, once_or_held, set_testcase,
)
from astaa_deft.engine.intercept.testcase import TestCase
from astaa_deft.model.sut import Spec

# Stamp and sequence fields, found by name anywhere in a message (brittle or not), and their faults: a
# stamp (any non-integer field) gets NaN, a jump back (previous stamp - 1 s), the far future or the previous
# stamp again; an integer (a sequence number, a stamp's seconds) the previous value again (a duplicate seq).
# A fault the field's codec cannot carry is left out for that field.
STAMP_NAMES = frozenset({"stamp", "timestamp", "seq", "sequence"})
STAMP_FAULTS = ("time.nan", "time.jump_back", "time.far_future", "time.repeat_previous")
SEQUENCE_FAULTS = ("time.repeat_previous",)


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
                found.append(Target(channel=channel, path=path, site=site, values=tuple(usable)))
        targets.extend(sorted(found, key=lambda t: t.site.field_type.kind in INT_KINDS))  # stable: spec order
    return targets


def stamp_testcase(testcase_id: str, rng: random.Random, target: Target, fault: Entry, *, scene: Scene) -> TestCase:
    """A stamp or sequence fault on one field: on one message, or (by chance, half of them) held."""
    start = scene.start(rng)
    return set_testcase(testcase_id, rng, target.channel.name, (Assignment(str(target.path), fault.ref),),
                        span=Span(start, *once_or_held(rng, start, scene.duration), scene.anchor), shape="stamp")


class Stamp(FaultFamily):
    name = "stamp"
    weight = 7
    rank = 4

    def targets(self, sources: Sources) -> Targets:
        return sources.stamps

    def draw(self, testcase_id: str, rng: random.Random, targets: Targets, scene: Scene) -> TestCase:
        channel = rng.choice(sorted(targets))
        target = rng.choice(targets[channel])
        return stamp_testcase(testcase_id, rng, target, rng.choice(target.values), scene=scene)


FAMILIES.register(Stamp.name, Stamp())
