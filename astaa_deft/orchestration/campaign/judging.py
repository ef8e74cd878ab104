"""The campaign's judging: one finished case into its bucket, a new bucket confirmed or not, a bug blamed.

A failing mutated case opens a bucket (or hits one); its re-runs and unmutated twins decide whether it
is a bug or flaky; a bug is blamed on a module and merged into an earlier bucket of the same root
cause. A part of :class:`~.campaign.Campaign` (its state: :class:`~.parts.CampaignParts`).
"""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

from astaa_deft.orchestration.campaign import signature as sig
from astaa_deft.orchestration.campaign.blame import BlameUnavailable, blame_logs
from astaa_deft.orchestration.journal.journal import Bucket
from astaa_deft.orchestration.journal.rows import BlameRow, CaseRow, NewBucket
from astaa_deft.orchestration.campaign.known import judged
from astaa_deft.orchestration.campaign.minimiser import Minimised
from astaa_deft.orchestration.campaign.minimiser import summary as minimised_summary
from astaa_deft.orchestration.journal.model import (
    BASELINE, BASELINE_FINDING, BUG, CONFIRMING, CONTROL, FLAKY, MUTATED, RERUN, BucketKind, BucketSignature,
    CaseOutcome, CaseStatus, FailureKey, PlannedCase,
)
from astaa_deft.orchestration.journal import verifications as verification
from astaa_deft.orchestration.campaign.parts import CampaignParts


def shows_failure(outcome: CaseOutcome, failing: CaseOutcome) -> bool:
    """``outcome`` breaks what ``failing`` was filed under (its primary finding's invariant, in the same module),
    first or among its other findings: a twin that collides after first grazing an obstacle shows the collision
    too."""
    wanted = sig.primary(failing)
    if wanted is None:
        return outcome.failed and outcome.verdict == failing.verdict
    return outcome.failed and any(sig.same_failure(f, wanted) for f in outcome.findings)


class Judging(CampaignParts):
    """A finished case judged and filed; a new bucket confirmed, decided and blamed."""

    # -- one finished case -----------------------------------------------------
    def _finished(self, case_id: str, outcome: CaseOutcome) -> list[PlannedCase]:
        self._running_cases.discard(case_id)
        row = self.journal.planned(case_id)
        kind, testcase = row.kind, self._testcase(row)
        outcome = sig.without_self_inflicted(outcome, testcase, self.spec)
        if kind in (MUTATED, RERUN):  # decictor: its oracle turns a run into a finding
            outcome = self.strategy.judge(case_id, testcase, outcome, kind == MUTATED)
        if kind != BASELINE:  # a known baseline finding counts only where this run makes it worse
            outcome = judged(outcome, self.known)
        new: list[PlannedCase] = []
        signature: BucketSignature | None = None
        key: FailureKey | None = None
        bucket: str | None = None
        if outcome.failed:
            key = sig.failure_key(outcome)
            clean = kind == BASELINE or (kind in (MUTATED, RERUN) and outcome.mutations == 0)
            if clean:  # no mutation acted: whatever failed, failed in a clean run — a baseline finding
                if kind != BASELINE:  # baseline runs are filed once calibrated (_file_baseline)
                    signature = BucketSignature.clean(key)
                    bucket = self._bucket(signature, outcome, case_id, BASELINE_FINDING)
                    self._learn_clean_failure(outcome)
            elif kind == MUTATED:
                signature = sig.signature(outcome, testcase)
                existing = self.journal.bucket_by_signature(signature)
                if existing is not None:
                    bucket = existing.bucket
                    self.journal.bucket_hit(bucket)
                    if bucket in self._fixed:  # verified fixed, and here it is again: it reopens
                        self._fixed.discard(bucket)
                        verification.reappeared(self.journal, bucket, case_id)
                        self.say(f"bucket {bucket} was verified fixed and reappeared in {case_id}: reopened")
                else:
                    bucket = self._bucket(signature, outcome, case_id, CONFIRMING)
                    new = self._plan_confirmation(bucket, row)
                    if not new:  # --reruns 0: nothing to confirm it with, filed as it is
                        self._decide(bucket)
            elif kind == RERUN:
                signature = sig.signature(outcome, testcase)
            elif kind == CONTROL:
                signature = BucketSignature.clean(key)
                self._learn_clean_failure(outcome)
        confirms = row.parent if kind in (RERUN, CONTROL) else None  # the bucket this run confirms
        if confirms is not None:
            first = self.journal.outcome(self.journal.planned(self.journal.bucket(confirms).first_case))
            same = outcome.failed and first is not None and shows_failure(outcome, first)
            if kind == RERUN and outcome.status == CaseStatus.DONE:
                self.journal.bucket_rerun(confirms, same and outcome.mutations > 0)
                if bucket is None and outcome.mutations > 0:  # filed under the bucket it re-runs
                    bucket = confirms
            elif kind == CONTROL and outcome.status == CaseStatus.DONE:
                self.journal.bucket_control(confirms, same)
                self._watch_timing(row, outcome)
        self.journal.finished(case_id, outcome, signature=signature, failure=key, bucket=bucket)
        self.journal.cost(case_id, outcome.cpu, os.getloadavg()[0], self.workers)
        if confirms is not None and not self.journal.unfinished(confirms):
            self._decide(confirms)
        if kind == MUTATED:
            self.strategy.observe(case_id, testcase, outcome)
        return new

    def _bucket(self, signature: BucketSignature, outcome: CaseOutcome, case_id: str, kind: BucketKind) -> str:
        existing = self.journal.bucket_by_signature(signature)
        if existing is not None:
            self.journal.bucket_hit(existing.bucket)
            return existing.bucket
        name = f"B{len(self.journal.buckets()) + 1:03d}"
        finding = sig.primary(outcome)
        family = signature.family
        invariant = finding.invariant if finding else "?"
        self.journal.add_bucket(NewBucket(name=name, signature=signature, verdict=outcome.verdict, invariant=invariant,
                                          module=finding.module if finding else None, first_case=case_id,
                                          without_mutation=kind == BASELINE_FINDING,
                                          after_cases=self.journal.finished_count() + 1, kind=kind))
        if kind == BASELINE_FINDING:
            self.say(f"new bucket {name}: {outcome.verdict}: {invariant} (without mutation: a baseline finding)")
        else:
            self.say(f"failure in {case_id}: {outcome.verdict}: {invariant} — {family}: confirming it ({name}:"
                     f" {self.config.reruns} re-run(s), {self._controls()} unmutated twin(s))")
        return name

    def _controls(self) -> int:
        """Unmutated twins of a new failure: as many as its re-runs (so the two rates compare)."""
        return self.config.reruns

    def _plan_confirmation(self, bucket: str, row: CaseRow) -> list[PlannedCase]:
        """The failing case again (its rate) and its unmutated twins (same params, no test case): interleaved,
        so both see the same load."""
        cases = []
        params = row.params
        for k in range(1, max(self.config.reruns, self._controls()) + 1):
            if k <= self.config.reruns:
                cases.append(PlannedCase(case_id=f"r-{bucket}-{k}", kind=RERUN, number=row.number, seed=row.seed,
                                         params=params, testcase=self._testcase(row), strategy=row.strategy,
                                         parent=bucket))
            if k <= self._controls():
                cases.append(PlannedCase(case_id=f"t-{bucket}-{k}", kind=CONTROL, number=row.number, seed=row.seed,
                                         params=params, testcase=None, strategy=row.strategy, parent=bucket))
        for case in cases:
            self._plan(case)
        return cases

    def _decide(self, name: str) -> None:
        """A confirming bucket's re-runs and twins are in: a bug, or flaky / the environment's doing."""
        bucket = self.journal.bucket(name)
        if bucket.kind != CONFIRMING:
            return
        reproduced = bucket.rerun_failures > 0 or self.config.reruns == 0
        twin_failed = bucket.control_failures > 0
        kind = BUG if reproduced and not twin_failed else FLAKY
        self.journal.bucket_kind(name, kind)
        rates = (f"re-runs {bucket.rerun_failures}/{bucket.reruns} failed the same way, unmutated twin(s)"
                 f" {bucket.control_failures}/{bucket.controls}")
        if kind == BUG:
            self.say(f"new bucket {name}: {bucket.verdict}: {bucket.invariant} — {bucket.family} ({rates})")
            self._blame(bucket)
        else:
            why = "the unmutated twin fails that way too" if twin_failed else "it did not reproduce"
            self.say(f"flaky/environment {name}: {bucket.invariant} — {bucket.family}: {why} ({rates});"
                     f" not filed as a bug")

    # -- blame: the module whose output departed first from the twins'; one bucket per root cause -----------
    def _blame(self, bucket: Bucket) -> None:
        """Name the module to blame for a new bug (blame.py), journal the chain, and merge the bucket into an
        earlier one of the same root cause: the same module to blame, wrong output, failure and field family."""
        first = self.journal.planned(bucket.first_case)
        outcome = first.outcome()
        if outcome is None or not outcome.log_path:
            return
        twins = [Path(o.log_path) for r in self.journal.cases(CONTROL) if r.parent == bucket.bucket
                 for o in (r.outcome(),) if o is not None and o.status == CaseStatus.DONE and o.log_path]
        reruns = [Path(o.log_path) for r in self.journal.cases(RERUN) if r.parent == bucket.bucket
                  for o in (r.outcome(),) if o is not None and o.log_path and o.mutations > 0
                  and shows_failure(o, outcome)]
        finding = sig.primary(outcome)
        try:
            found = blame_logs(self.spec, [Path(outcome.log_path), *reruns], twins, self.timing.anchor,
                               invariant=bucket.invariant, finding_module=finding.module if finding else None)
        except BlameUnavailable as exc:
            self.journal.note("blame", f"{bucket.bucket}: no blame: {exc}")
            return
        replayed = self._module_level_blame(bucket.bucket, first)  # a module-level finding's live case
        if replayed is not None:  # the module whose replay failed is to blame (never a plant, never the value)
            found = replace(found, module=replayed[0], how=found.how if found.module == replayed[0] else "replay")
        identity = (None if found.root_cause is None else
                    f"{found.root_cause}|{found.wrong_output}|{sig.failure_signature(outcome)}|"
                    f"{sig.field_family(bucket.family)}")
        self.journal.blamed(BlameRow(bucket=bucket.bucket, module=found.module, output=found.output, how=found.how,
                                     chain=found.chain, detail=found.detail, twins=found.twins, identity=identity,
                                     replay=replayed[1] if replayed else None))
        self.say(f"  {bucket.bucket} blame: {found.root_cause or '?'} ({found.chain}; {found.detail})")
        if identity is None:
            return
        blames = self.journal.blames()
        same = next((b for b in self.journal.buckets(include_merged=False)
                     if b.bucket != bucket.bucket and b.is_bug and blames.get(b.bucket) is not None
                     and blames[b.bucket].identity == identity), None)
        if same is not None:
            self.journal.merge_bucket(bucket.bucket, same.bucket)
            text = (f"bucket {bucket.bucket} ({bucket.family}) merged into {same.bucket} ({same.family}): one root"
                    f" cause — {found.root_cause} to blame, {found.wrong_output}, {sig.field_family(bucket.family)}")
            self.journal.note("blame", text)
            self.say(f"  {text}")

    def _replay_confirms_blame(self, name: str, result: Minimised) -> None:
        """A minimisation that reproduced the failure in a replay of the module to blame alone, with the culprit
        frames, confirms the blame: journalled with it."""
        blamed = self.journal.blames().get(name)
        if blamed is None or blamed.module is None or result.exit_code != 0:
            return
        summary = minimised_summary(result.out_dir)
        if summary.get("tester") != "replay" or summary.get("replayed_module") != blamed.module:
            return
        frames = summary.get("frames")
        kept = frames.get("after") if isinstance(frames, dict) else None
        how = (f"a replay of {blamed.module} alone over {kept} frame(s) with the culprit fails as the run did"
               if kept is not None else f"a replay of {blamed.module} alone with the culprit fails as the run did")
        self.journal.blamed(replace(blamed, replay=how))
        self.say(f"  {name} blame confirmed: {how}")

