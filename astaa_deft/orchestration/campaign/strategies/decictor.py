"""Decictor as campaign strategies: ``decictor``, ``decictor-random``, ``decictor-random-delta``.

The campaign's clean baseline run is the seed (its ego path is the optimal
decision; it must reach its goal). Each case is a test case of
``participant`` policies on the spec's participant channel (the proxy
injects them into the planner's input); after the run, ``judge`` reads the
case's log and applies Decictor's oracle (``astaa_deft.analysis.decictor.oracle``): a
non-optimal decision becomes a ``path_consistency`` finding (CRASH class
Hindering), so it lands in a campaign bucket like any other failure.
``finish`` turns each such bucket into DeFT module tests with a
path-consistency oracle and writes ``decictor.html``: seed vs mutated paths.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from collections.abc import Callable

from astaa_deft.analysis.decictor.config import DecictorConfig, read_config
from astaa_deft.analysis.decictor.feasible import Area, ForbiddenRegion
from astaa_deft.analysis.decictor.observe import ObservationError, observe_log
from astaa_deft.analysis.decictor.oracle import Lane, LaneGrid, RunObservation
from astaa_deft.analysis.decictor.search import Scene, Search
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.engine.intercept.actions.participant import Participant
from astaa_deft.engine.intercept.dictionary import Dictionary
from astaa_deft.engine.intercept.testcase import Policy, TestCase
from astaa_deft.model.records import Verdict
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.journal.model import CaseOutcome, Finding
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.orchestration.campaign.strategies.base import STRATEGIES, Proposal, Strategy

INVARIANT = "path_consistency"
CRASH = Verdict.HINDERING
AREA_MARGIN = 4.0  # m beyond the outer lane edges where participants may stand
AREA_BEHIND, AREA_AHEAD = 10.0, 30.0  # m before the seed path's start and past its end
RESULT_FILE = "decictor.json"


def area_around(seed: RunObservation, lanes: tuple[Lane, ...]) -> Area:
    xs = [s.x for s in seed.ego.states]
    ys = [y for lane in lanes for _, y in lane.centre]
    half = max(lane.width for lane in lanes) / 2
    return Area(min(xs) - AREA_BEHIND, max(xs) + AREA_AHEAD, min(ys) - half - AREA_MARGIN,
                max(ys) + half + AREA_MARGIN)


def scene_testcase(scene: Scene, case_id: str, seed: int, channel: str) -> TestCase:
    policies = tuple(Policy(id=f"p{k + 1}", action=p, channels=(channel,)) for k, p in enumerate(scene.participants))
    described = ", ".join(f"{p.kind} {p.id} at ({p.x:g}, {p.y:g})" + (" moving" if p.path else "")
                          for p in scene.participants) or "no participant (the seed)"
    return TestCase(id=case_id, seed=seed, description=f"decictor ({scene.operator}): {described}", policies=policies)


def scene_of(testcase: TestCase) -> Scene:
    return Scene(tuple(p.action for p in testcase.policies if isinstance(p.action, Participant)))


@STRATEGIES.register_class
class DecictorStrategy(Strategy):
    name = "decictor"
    exports_own_findings = True  # finish(): module tests and decictor.html instead of minimisation
    mode = "decictor"

    def __init__(self, spec: Spec, dictionary: Dictionary, seed: int, duration: float) -> None:
        self.spec = spec
        self.config: DecictorConfig = read_config(spec)  # a spec without lanes fails here: exit 2
        self.seed = seed
        self.search: Search | None = None
        self.seed_case: str | None = None
        self.seed_log: str | None = None
        self.lanes: tuple[Lane, ...] = ()
        self.why_no_seed = "no clean baseline run finished"

    # -- the seed ----------------------------------------------------------------
    def observe_baseline(self, case_id: str, outcome: CaseOutcome) -> None:
        if self.search is not None or outcome.status != "done" or not outcome.log_path:
            return
        try:
            logged = observe_log(Path(outcome.log_path), self.spec, self.config)
        except (ObservationError, InputError) as exc:
            self.why_no_seed = str(exc)
            return
        seed_run = logged.observation
        if not seed_run.goal_reached or seed_run.collision:
            self.why_no_seed = f"baseline {case_id} did not reach its goal cleanly"
            return
        self.lanes = logged.lanes
        region = ForbiddenRegion(seed_run.ego, self.config.dt, self.config.clearance)
        self.search = Search(self.mode, self.seed, seed_run, LaneGrid(self.lanes),
                             area=area_around(seed_run, self.lanes), region=region)
        self.seed_case, self.seed_log = case_id, outcome.log_path

    def _search(self) -> Search:
        if self.search is None:
            raise InputError(Problem("--strategy decictor", None, None,
                                     f"no seed run to compare with: {self.why_no_seed}",
                                     "the clean baseline run must reach its goal (check the SUT and --horizon)"))
        return self.search

    # -- ask / tell ----------------------------------------------------------------
    def propose(self, number: int) -> Proposal:
        scene = self._search().propose(number)
        return Proposal(scene_testcase(scene, f"tc-{number:06d}", number, self.config.participants.channel),
                        parent=self.seed_case)

    def judge(self, case_id: str, testcase: TestCase | None, outcome: CaseOutcome, learn: bool = True) -> CaseOutcome:
        """The outcome with a path_consistency finding when the run was a non-optimal decision."""
        if testcase is None or outcome.status != "done" or not outcome.log_path:
            return outcome
        search = self._search()
        scene = scene_of(testcase)
        try:
            run = observe_log(Path(outcome.log_path), self.spec, self.config).observation
        except (ObservationError, InputError) as exc:
            return replace(outcome, status="error", verdict="?", error=f"decictor: {exc}")
        if learn:
            verdict = search.observe(scene, run)
        else:
            from astaa_deft.analysis.decictor.oracle import judge

            verdict = judge(search.seed_run, run, scene.participants, search.grid)
        record = {"case": case_id, "non_optimal": verdict.non_optimal, "reason": verdict.reason,
                  "path_distance": verdict.path_distance, "behaviour_mmd": verdict.behaviour_mmd,
                  "worst_lane": verdict.consistency.worst_lane if verdict.consistency else None,
                  "dissimilarity": verdict.consistency.dissimilarity if verdict.consistency else None,
                  "seed_log": self.seed_log}
        (Path(outcome.log_path).parent / RESULT_FILE).write_text(json.dumps(record, indent=1) + "\n")
        if not verdict.non_optimal:
            return outcome
        module = self.spec.planner.module if self.spec.planner is not None else None
        finding = Finding(invariant=INVARIANT, crash=CRASH, module=module, channel=self.config.participants.channel,
                          detail=verdict.reason)
        verdict_class = CRASH if outcome.verdict == Verdict.PASS else outcome.verdict
        return replace(outcome, verdict=verdict_class, findings=[finding, *outcome.findings],
                       summary=f"{verdict.reason}; {outcome.summary}")

    # -- the end ---------------------------------------------------------------------
    def finish(self, journal: Journal, out: Path, spec_path: Path, say: Callable[[str], None]) -> None:
        from astaa_deft.orchestration.campaign.strategies.decictor_export import export_findings

        export_findings(self, journal, out, say=say)


@STRATEGIES.register_class
class DecictorRandomDeltaStrategy(DecictorStrategy):
    name = "decictor-random-delta"
    mode = "random-delta"


@STRATEGIES.register_class
class DecictorRandomStrategy(DecictorStrategy):
    name = "decictor-random"
    mode = "random"
