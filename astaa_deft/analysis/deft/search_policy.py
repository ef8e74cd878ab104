"""Which candidate frame to try first, and how long one may run: learned from the run being extracted.

Pure logic, no I/O. Extraction tries an output's candidate frames until one
reproduces it; every wrong frame tried first costs a planner step (an RRT*
search on a wrong frame can run for seconds). Two things about a run repeat
from output to output, so the outputs already extracted predict the next:

* **the way the right frame is derived** (:class:`WinningPatterns`): e.g.
  a planner whose loop plans on the oldest trigger not yet answered, or one
  that usually gets the pose before the trigger of the same simulator tick.
  Each candidate carries the ways it was derived (``Candidate.patterns``);
  the ways that won recently come first, the generic order breaks ties.
* **how long a right frame takes** (:class:`StepBudget`): the planner had at
  most the recorded window (from its trigger, or its previous output, to
  the output) for the step that produced an output. Replayed steps of the
  accepted frames show how replay speed compares with that window; a
  candidate running several times longer than that is most likely a wrong
  frame searching in vain, and is cut — and retried under the full limit
  if no other candidate is accepted, so no output is lost to the cut.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Hashable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Protocol, TypeVar

from astaa_deft.analysis.deft.frames import Candidate, first_output_ways, ways_where


class HasPatterns(Protocol):
    @property
    def patterns(self) -> Iterable[Hashable]: ...


C = TypeVar("C", bound=HasPatterns)
RECENCY = 0.9  # a win's weight shrinks by this factor with every later output: recent wins count more


@dataclass
class WinningPatterns:
    """Scores of the ways candidates were derived, by the (recency-weighted) outputs they reproduced."""

    recency: float = RECENCY
    scores: dict[Hashable, float] = field(default_factory=dict)

    rule_scores: dict[Hashable, float] = field(default_factory=dict)  # the same by the way's first part alone

    def record(self, winner: HasPatterns) -> None:
        """The kept candidate of one output (accepted): each way it was derived wins."""
        for scores in (self.scores, self.rule_scores):
            for pattern in scores:
                scores[pattern] *= self.recency
        for pattern in winner.patterns:
            self.scores[pattern] = self.scores.get(pattern, 0.0) + 1.0
        for rule in {_rule(pattern) for pattern in winner.patterns}:
            self.rule_scores[rule] = self.rule_scores.get(rule, 0.0) + 1.0

    def score(self, candidate: HasPatterns) -> float:
        return max((self.scores.get(p, 0.0) for p in candidate.patterns), default=0.0)

    def rule_score(self, candidate: HasPatterns) -> float:
        return max((self.rule_scores.get(_rule(p), 0.0) for p in candidate.patterns), default=0.0)

    def rank(self, candidates: Sequence[C], by_rule: bool = False) -> list[C]:
        """The candidates, best-scoring way first; equal scores keep the given (generic) order.

        ``by_rule``: among equal scores, the candidates whose trigger rule
        (the way's first part: newest, busy, …) won most come first — where
        the inputs' offsets jitter from output to output under load, the
        trigger rule still repeats.
        """
        if by_rule:
            return sorted(candidates, key=lambda c: (self.score(c), self.rule_score(c)), reverse=True)
        return sorted(candidates, key=self.score, reverse=True)  # sorted() is stable


def _rule(pattern: Hashable) -> Hashable:
    """A way's trigger rule: the first part of a (rule, offsets) pattern; any other pattern is its own rule."""
    return pattern[0] if isinstance(pattern, tuple) and pattern else pattern


def first_cycle_first(candidates: Sequence[Candidate]) -> list[Candidate]:
    """For a first output (nothing learned yet): the frame at the first trigger the planner could plan from.

    A first cycle is often the slowest (a planner building its state) and
    answers the first trigger it could plan from (docs/performance.md,
    "analysis"). A planner that keeps up answers the newest, one more step. Only where several candidates are
    tried (a process replay tries one: the generic order keeps the newest).
    """
    def at_own_time(rule: str) -> list[Candidate]:
        return [c for c in candidates
                if any(r == rule and all(offset == 0 for _, offset in offsets) for r, offsets in c.patterns)]

    # The rules a first output tries first, by rank: the first trigger every input had been heard by, then the
    # very first one (some input absent then).
    first: list[Candidate] = []
    for way in first_output_ways():
        first += [c for c in at_own_time(way) if c not in first]
    return first + [c for c in candidates if c not in first]


def likely_ways() -> frozenset[str]:
    """The ways of the frame rules a module follows (``FrameRule.likely``: not merely a trigger between), and of
    the times a module reads its inputs at."""
    return ways_where(lambda rule: rule.likely)


def nearest_first(candidates: Sequence[Candidate]) -> list[Candidate]:
    """The candidates, likeliest first: those of the newest, busy, oldest (or first) trigger before those of
    a trigger between; then those closest to their trigger's own frame; the given order breaks ties.

    Closeness is the largest input offset from the frame at the trigger's
    time (the best of the candidate's ways): an input the planner got a
    message or two before or after the recorder is delivery jitter, twenty
    messages is a planner that read its inputs much later. For an expensive
    output, where every wrong frame tried costs a planner step, the frames
    near each likely trigger's own time come before the far frames of any.
    """
    likely = likely_ways()

    def likelihood(candidate: Candidate) -> tuple[int, int]:
        return min(((rule not in likely, max((abs(offset) for _, offset in offsets), default=0))
                    for rule, offsets in candidate.patterns), default=(1, 0))

    return sorted(candidates, key=likelihood)  # sorted() is stable


LIMIT_FACTOR = 3.0  # a candidate may take this many times its expected step before it is cut
MIN_TIGHT_S = 0.25  # never cut sooner: process start-up and scheduling noise on a loaded machine
NEIGHBOUR_FACTOR = 2.0  # an expensive output's candidate may take this many of its neighbours' steps (CPU)
NEIGHBOURS = 5  # the accepted steps of this many outputs before are an expensive output's neighbours
NOISE_S = 0.01  # steps shorter than this say more about timer and scheduler noise than about replay speed


@dataclass
class StepBudget:
    """A tight per-candidate time limit from the steps accepted so far in this extraction.

    ``window_s`` of an output is the longest the recorded planner can have
    worked on it (output time minus the later of its earliest candidate
    trigger and the previous output). ``slowdown`` is the largest ratio of
    an accepted replayed step to its window seen so far (at least 1: replay
    is assumed no faster than the recording).
    """

    factor: float = LIMIT_FACTOR
    min_s: float = MIN_TIGHT_S
    slowdown: float = 1.0
    accepted_steps: int = 0
    neighbours: deque[float] = field(default_factory=lambda: deque(maxlen=NEIGHBOURS))  # recent steps, CPU s

    def record(self, step_s: float, window_s: float, expensive: bool = False) -> None:
        """An accepted candidate's replayed step time (CPU seconds) and its output's recorded window;
        ``expensive``: the output's, whose steps are the neighbours of the next expensive one."""
        self.accepted_steps += 1
        if expensive:
            self.neighbours.append(step_s)
        if window_s > 0 and step_s >= NOISE_S:
            self.slowdown = max(self.slowdown, step_s / window_s)

    def limit(self, window_s: float, full_limit_s: float) -> float:
        """Seconds a candidate of this output may run before it is cut (never more than the full limit).

        Before any step was accepted nothing is known about replay speed: the full limit.
        """
        if self.accepted_steps == 0:
            return full_limit_s
        return min(full_limit_s, max(self.min_s, self.factor * self.slowdown * window_s))

    def neighbour_limit(self, full_limit_s: float) -> float:
        """Seconds (CPU) a candidate of an expensive output may run: about one step of the planner as the
        accepted steps of the expensive outputs just before measured it, from their own states (never more
        than the full limit; the full limit while none was accepted)."""
        if not self.neighbours:
            return full_limit_s
        return min(full_limit_s, max(self.min_s, NEIGHBOUR_FACTOR * max(self.neighbours)))


# An expensive output tries at most this many candidates (nearest their trigger, in the learned order), each
# a planner step: extraction stays a few replays long even when no frame reproduces an output (a planner not
# bit-stable across copies, or an input the log lacks); the closest of them is kept.
EXPENSIVE_TRIES = 8
# … of which at most this many answer one trigger message, when others are left out: the likeliest trigger's
# frames differ only in the other inputs' offsets, and eight of them left the next trigger's likeliest frame
# out (slow_planner: its one wrong frame, and the warm state carried it into 10 of 13 outputs).
PER_TRIGGER = 4


def _varied(ranked: Sequence[Candidate], trigger: str | None) -> list[Candidate]:
    """The likeliest EXPENSIVE_TRIES of ``ranked``, at most PER_TRIGGER of one ``trigger`` message (in
    rank order; those over the cap come back only where too few others are left)."""
    if trigger is None:
        return list(ranked[:EXPENSIVE_TRIES])
    per: dict[int | None, int] = {}
    chosen: list[int] = []
    for index, cand in enumerate(ranked):
        key = cand.choice.get(trigger)
        if per.get(key, 0) < PER_TRIGGER:
            per[key] = per.get(key, 0) + 1
            chosen.append(index)
            if len(chosen) == EXPENSIVE_TRIES:
                break
    if len(chosen) < EXPENSIVE_TRIES:
        chosen += [i for i in range(len(ranked)) if i not in chosen][:EXPENSIVE_TRIES - len(chosen)]
    return [ranked[i] for i in sorted(chosen)]


@dataclass
class SearchMemory:
    """What an extraction learned from the outputs kept so far: the order and the time limit of the next.

    The ways that won are learned twice: over every output, and over the
    expensive ones alone (a busy planner plans otherwise than an idle one).
    """

    winning: WinningPatterns = field(default_factory=WinningPatterns)
    winning_expensive: WinningPatterns = field(default_factory=WinningPatterns)
    budget: StepBudget = field(default_factory=StepBudget)

    def order(self, generic: Sequence[Candidate], *, expensive: bool, first: bool, trigger: str | None = None
              ) -> tuple[list[Candidate], bool]:
        """(the candidates to try, in order; whether some were left out): an expensive output's likeliest
        ``EXPENSIVE_TRIES`` (:func:`nearest_first`, ranked by the expensive outputs' ways and rules; at most
        ``PER_TRIGGER`` of one ``trigger`` message while others are left out), else all, ranked by every
        output's ways; a ``first`` output's first plannable trigger first."""
        if expensive:
            options = self.winning_expensive.rank(nearest_first(generic), by_rule=True)
        else:
            options = self.winning.rank(generic)
        if first:
            options = first_cycle_first(options)
        if expensive and len(options) > EXPENSIVE_TRIES:
            return _varied(options, trigger), True
        return options, False

    def learn(self, kept: Candidate, step_s: float | None = None, window_s: float = 0.0,
              expensive: bool = False) -> None:
        """An accepted candidate: its ways win; its step (CPU seconds, if measured) against its window."""
        self.winning.record(kept)
        if expensive:
            self.winning_expensive.record(kept)
        if step_s is not None:
            self.budget.record(step_s, window_s, expensive)
