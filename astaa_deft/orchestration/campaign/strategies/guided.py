"""Guided search: mutate the test cases that brought an invariant closest to breaking.

In the spirit of falsification (S-TaLiRo, PSY-TaLiRo) and PGFuzz: each run
reports, per invariant, how close it came to breaking (``CaseOutcome.margins``:
the bound margin or STL robustness, 0 when it broke). A case joins the corpus
when it brought some invariant clearly closer (by ``CLOSER``) than the clean
baseline runs and every case before; while the corpus holds something, the
next cases are, half of the time, a corpus entry changed in one way (another
value for a field, another field, a shifted window, a repeated instead of a
one-message action, or one more policy) — the closer an entry came, the more
often it is chosen — and otherwise the random strategy's next coverage case
(its schedule walked without gaps), so the search never stops exploring.

Without evidence there is nothing to steer by: until a case comes closer than
the baseline, guided proposes exactly the random strategy's cases, in the
same order, so it is never slower than random on a defect that only the first
visit of a value finds (measured: every seeded demo defect is such a one;
docs/campaigns.md). Deterministic for a given seed and order of results.
"""

from __future__ import annotations

import math
import random
from collections.abc import Collection, Sequence
from dataclasses import replace

from astaa_deft.engine.intercept import generate as gen
from astaa_deft.engine.intercept.actions.set import Assignment, Set
from astaa_deft.engine.intercept.dictionary import Dictionary
from astaa_deft.engine.intercept.testcase import Selection, TestCase
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.journal.model import CaseOutcome, PlannedCase
from astaa_deft.orchestration.campaign.strategies.base import STRATEGIES, Proposal, Strategy, Timing
from astaa_deft.orchestration.campaign.strategies.random import RandomStrategy

EXPLOIT_SHARE = 0.5
# A margin counts as closer when it is below the best so far (the baseline's, at first) by this share of
# it: run-to-run jitter of a clean stack (a few %) must not fill the corpus with cases that changed nothing.
CLOSER = 0.1
CORPUS_LIMIT = 32
OPERATORS = ("value", "field", "window", "action", "policy")


@STRATEGIES.register_class
class GuidedStrategy(Strategy):
    name = "guided"

    def __init__(self, spec: Spec, dictionary: Dictionary, seed: int, duration: float) -> None:
        self.fresh = RandomStrategy(spec, dictionary, seed, duration)
        self.seed = seed
        self.duration = duration
        self.targets = {(t.channel.name, str(t.path)): t for ts in self.fresh.by_channel.values() for t in ts}
        self.best: dict[str, float] = {}  # invariant → closest approach so far
        self.corpus: list[tuple[str, TestCase]] = []  # (case id, test case), newest last
        self.closeness: dict[str, float] = {}  # corpus case → the smallest margin it reached
        self.fresh_planned = 0  # schedule cases proposed so far (the next one is fresh_planned + 1)

    def leave_out(self, fields: Collection[tuple[str, str]]) -> int:
        left = self.fresh.leave_out(fields)
        self.targets = {(t.channel.name, str(t.path)): t for ts in self.fresh.by_channel.values() for t in ts}
        return left

    def calibrate(self, timing: Timing) -> None:
        self.fresh.calibrate(timing)
        self.duration = timing.live

    def _exploits(self, number: int) -> bool:
        """Whether case ``number`` may derive from the corpus (if the corpus holds anything by then)."""
        return random.Random(f"guided/{self.seed}/{number}").random() < EXPLOIT_SHARE

    def resume(self, planned: Sequence[PlannedCase]) -> None:
        """The cases a resumed campaign had planned already: the schedule goes on after the schedule cases
        among them (those without a parent), none proposed twice."""
        self.fresh_planned = sum(1 for case in planned if case.parent is None)

    def propose(self, number: int) -> Proposal:
        rng = random.Random(f"guided/{self.seed}/{number}")
        rng.random()  # the draw _exploits made
        if not (self.corpus and self._exploits(number)):
            self.fresh_planned += 1
            fresh = self.fresh.propose(self.fresh_planned).testcase
            return Proposal(replace(fresh, id=f"tc-{number:06d}"))
        # Steer: the closer an entry came to breaking an invariant, the more often it is the parent.
        weights = [1.0 / (self.closeness.get(case, 1.0) + 0.05) for case, _ in self.corpus]
        parent_id, parent = rng.choices(self.corpus, weights=weights)[0]
        operator = rng.choice(OPERATORS)
        child = self._mutate(parent, operator, rng, number)
        return Proposal(child, parent=parent_id)

    def observe_baseline(self, case_id: str, outcome: CaseOutcome) -> None:
        """A clean run: where each invariant stands without mutation (what a case must beat)."""
        if outcome.status != "done":
            return
        for invariant, margin in outcome.margins.items():
            if math.isfinite(margin):
                self.best[invariant] = min(margin, self.best.get(invariant, math.inf))

    def observe(self, case_id: str, testcase: TestCase | None, outcome: CaseOutcome) -> None:
        if testcase is None or outcome.status != "done":
            return
        closer = False
        for invariant, margin in outcome.margins.items():
            best = self.best.get(invariant, math.inf)
            if math.isfinite(margin) and margin < best * (1.0 - CLOSER):
                self.best[invariant] = margin
                closer = True
        if closer:
            self.corpus.append((case_id, testcase))
            self.closeness[case_id] = min(m for m in outcome.margins.values() if math.isfinite(m))
            del self.corpus[:-CORPUS_LIMIT]

    # -- mutation operators ------------------------------------------------
    def _mutate(self, parent: TestCase, operator: str, rng: random.Random, number: int) -> TestCase:
        policies = list(parent.policies)
        index = rng.randrange(len(policies))
        policy = policies[index]
        channel = policy.channels[0] if policy.channels else None
        if operator == "policy":
            extra = self.fresh.propose(number).testcase.policies[0]
            policies.append(replace(extra, id=f"p{len(policies) + 1}"))
        elif isinstance(policy.action, Set) and operator in ("value", "field") and channel is not None:
            fields = list(policy.action.fields)
            if operator == "value":
                k = rng.randrange(len(fields))
                target = self.targets.get((channel, fields[k].path))
                if target is not None:
                    fields[k] = Assignment(fields[k].path, rng.choice(target.values).ref)
            else:
                taken = {a.path for a in fields}
                options = [t for (ch, path), t in sorted(self.targets.items()) if ch == channel and path not in taken
                           and not any(gen._overlaps(t.path, self.targets[(ch, p)].path)
                                       for p in taken if (ch, p) in self.targets)]
                if options:
                    t = rng.choice(options)
                    fields.append(Assignment(str(t.path), rng.choice(t.values).ref))
            policies[index] = replace(policy, action=Set(tuple(fields)))
        elif operator == "window":
            start = min(max(0.0, round(policy.window.start + rng.uniform(-2.0, 2.0), 1)), self.duration)
            end = policy.window.end
            if end is not None:
                end = max(round(start + 0.1, 1), end)
            policies[index] = replace(policy, window=replace(policy.window, start=start, end=end))
        else:  # action: one message → every message (or every n-th) in a short window
            start = policy.window.start
            end = round(start + rng.uniform(1.0, 5.0), 1)
            policies[index] = replace(policy, window=replace(policy.window, start=start, end=end),
                                      selection=rng.choice([Selection(), Selection(every=rng.choice([2, 5]))]))
        return TestCase(id=f"tc-{number:06d}", seed=rng.getrandbits(32),
                        description=f"guided ({operator}) from {parent.id}: "
+ parent.description, policies=tuple(policies))
