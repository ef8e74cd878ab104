"""Random generation, coverage first: every channel and field early, then ASTAA's weighted draws.

A campaign runs a few hundred cases, not ASTAA's thousands, so case ``n``
comes from a schedule (:func:`astaa_deft.engine.intercept.generate.coverage_round`):
the first ``COVERAGE_ROUNDS`` rounds each visit every (channel, field) once
with a value of the round's class (non-finite or empty first, then extreme
magnitudes, …), a third of them holding the value (sustained), apply one
message fault (reorder, delay, duplicate, drop) to every channel and a stamp
or sequence fault to a few (about 7 % of a round, NaN first); after them,
cases alternate between further rounds and the weighted generation (every
registered fault family by its weight, message faults included). Every
``SEMANTIC_EVERY``-th case is instead a probe of the semantic fault families'
own schedule (:func:`astaa_deft.engine.intercept.generate.semantic_probe`:
the families take turns, each walking its targets with its most telling
value first), so plausible-but-wrong values are tried from the first minutes on.
Windows fall inside the run's live part, counted from the first message of
the channel that came last in the baseline runs (the
campaign's :class:`Timing`), so a case mutates the running SUT, not its
start-up. Deterministic: case ``n`` depends on the seed, ``n`` and the
timing only — the same cases locally and on a cluster, in any order.
"""

from __future__ import annotations

import random
from collections.abc import Collection

from astaa_deft.engine.intercept import generate as gen
from astaa_deft.engine.intercept.dictionary import Dictionary
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.campaign.strategies.base import STRATEGIES, Proposal, Strategy, Timing

ID_WIDTH = 6
COVERAGE_ROUNDS = 2  # pure coverage rounds before weighted draws are mixed in
SEMANTIC_EVERY = 2  # every other case probes a semantic fault family (when the spec offers one a target)


@STRATEGIES.register_class
class RandomStrategy(Strategy):
    name = "random"

    def __init__(self, spec: Spec, dictionary: Dictionary, seed: int, duration: float) -> None:
        self._target(gen.FaultTargets.of(spec, dictionary))  # InputError: nothing to mutate
        self.seed = seed
        self.timing = Timing(None, duration)
        self._rounds: dict[int, list[gen.Probe]] = {}

    def calibrate(self, timing: Timing) -> None:
        """Windows from now on count from ``timing.anchor`` and fall inside ``timing.live`` seconds."""
        self.timing = timing

    def leave_out(self, fields: Collection[tuple[str, str]]) -> int:
        """Fields no module reads leave every family's targets (a channel left with none leaves the family)."""
        targets, left = gen.without_fields(self.targets, fields)
        self._target(targets)
        self._rounds.clear()
        return left

    def _target(self, targets: gen.FaultTargets) -> None:
        """Draw from ``targets``: one-field faults by channel, and the stamp faults (none: the spec has none)."""
        self.targets = targets
        self.by_channel = targets.by_family["single"]
        self.stamps = targets.by_family.get("stamp", {})

    @property
    def round_length(self) -> int:
        return len(self._round(0))

    def _round(self, number: int) -> list[gen.Probe]:
        if number not in self._rounds:
            self._rounds[number] = gen.coverage_round(self.by_channel, self.seed, number, self.stamps)
        return self._rounds[number]

    def propose(self, number: int) -> Proposal:
        testcase_id = f"tc-{number:0{ID_WIDTH}d}"
        rng = random.Random(f"{self.seed}/{number}")
        index = number - 1
        if self.targets.semantic():  # every SEMANTIC_EVERY-th case: the semantic families' schedule
            if index % SEMANTIC_EVERY == SEMANTIC_EVERY - 1:
                found = gen.semantic_probe(self.targets, self.seed, index // SEMANTIC_EVERY)
                assert found is not None
                probe, lap = found
                testcase = gen.probe_testcase(testcase_id, rng, probe, lap, duration=self.timing.live,
                                              anchor=self.timing.anchor)
                return Proposal(testcase)
            index -= index // SEMANTIC_EVERY
        covered = COVERAGE_ROUNDS * self.round_length
        if index >= covered:  # after the pure rounds: every other case is a weighted draw
            if (index - covered) % 2:
                testcase = gen.weighted_testcase(testcase_id, rng, self.targets, self.timing.live,
                                                 anchor=self.timing.anchor, message_faults=True)
                return Proposal(testcase)
            index = covered + (index - covered) // 2
        round_number, position = divmod(index, self.round_length)
        probe = self._round(round_number)[position]
        testcase = gen.probe_testcase(testcase_id, rng, probe, round_number, duration=self.timing.live,
                                      anchor=self.timing.anchor)
        return Proposal(testcase)
