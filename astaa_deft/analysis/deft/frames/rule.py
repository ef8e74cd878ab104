"""The frame rules' extension point: :class:`FrameRule` and the ``FRAME_RULES`` registry.

A frame rule is one way a module may have chosen the inputs of an output:
which trigger message it answered (the newest, the oldest not yet answered,
the newest when its previous cycle ended…), or a whole frame read otherwise
(the inputs as logged before the newest trigger). Each rule is one module
of ``frames/rules/`` that registers its ``FrameRule`` at import; the
registry imports them all on first read. :func:`..candidates` walks the
rules in ``order``: each places the triggers it names, in its own order,
after those of the rules before it, and the frames of every placed trigger
are the candidates, tried in that order.

What the search makes of a rule's frames is said on the rule, not by its
name elsewhere: ``likely`` (a way a module follows, tried before the
triggers merely between), ``first_output`` (a first output, with nothing
learned yet, tries this rule's frames first, by rank).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

from astaa_deft.analysis.deft.frames.context import OutputContext
from astaa_deft.analysis.deft.frames.streams import Candidate
from astaa_deft.model.registry import Registry

# A trigger a rule places: (index into the trigger stream, the way its frames carry — None: placed in the
# trying order here, named by a later rule's ``names_rest``).
Trigger = tuple[int, str | None]


@dataclass(frozen=True, kw_only=True)
class FrameRule:
    """One way of choosing an output's frame, as the search sees it.

    ``name``: the registry's key (and the way its frames carry unless
    ``ways`` says otherwise). ``order``: where its triggers come among the
    rules' (lower first; ties by name). Hooks, each optional:
    ``triggers(ctx)``: the triggers it places, in order; ``names_rest(ctx)``:
    the way given, at this rule's turn, to every trigger placed so far that
    no rule named; ``frame(ctx)``: a whole frame, tried after every
    trigger's frames. A rule with no hook names a way derived elsewhere
    (frames read at a time, the plain walk), registered for its traits.
    """

    name: str
    order: int
    triggers: Callable[[OutputContext], Iterable[Trigger]] | None = None
    names_rest: Callable[[OutputContext], str] | None = None
    frame: Callable[[OutputContext], Candidate | None] | None = None
    ways: tuple[str, ...] = ()  # every way its frames may carry (empty: just its name)
    likely: bool = False  # a way a module follows, not merely a trigger between (search_policy.nearest_first)
    first_output: int | None = None  # rank among the frames a first output tries first (search_policy)

    @property
    def all_ways(self) -> tuple[str, ...]:
        return self.ways or (self.name,)


FRAME_RULES: Registry[FrameRule] = Registry("frame rule", "astaa_deft.analysis.deft.frames.rules")


def register(rule: FrameRule) -> FrameRule:
    """Add ``rule`` to ``FRAME_RULES`` (a rule module's one call)."""
    return FRAME_RULES.register(rule.name, rule)


def ordered() -> list[FrameRule]:
    """The rules in their ``order`` (ties by name)."""
    return sorted(FRAME_RULES.values(), key=lambda rule: (rule.order, rule.name))


def ways_where(trait: Callable[[FrameRule], bool]) -> frozenset[str]:
    """Every way of the rules with ``trait``."""
    return frozenset(way for rule in FRAME_RULES.values() if trait(rule) for way in rule.all_ways)


def first_output_ways() -> list[str]:
    """The ways a first output, with nothing learned yet, tries first: the ``first_output`` rules' by rank."""
    ranked = sorted((rule.first_output, rule.name, rule) for rule in FRAME_RULES.values()
                    if rule.first_output is not None)
    return [way for _, _, rule in ranked for way in rule.all_ways]
