"""The campaign's baseline: clean runs of every param value, and what they say about the unmutated SUT.

Where the SUT stands without mutation: the horizon a case may run (derived from the clean runs), when
the stack is live (the strategy's timing), how long a module whose exit ends the run takes from its last
message to its exit (its shutdown delay, with headroom: the end of every later run is dated by it), and
the invariants it breaks by itself (known baseline findings, filed into baseline-finding buckets and
learnt again from every clean run that fails later).
A part of :class:`~.campaign.Campaign` (its state: :class:`~.parts.CampaignParts`).
"""

from __future__ import annotations

from astaa_deft.engine.session.run_end import SHUTDOWN_GRACE_NS
from astaa_deft.model.errors import AstaaDeftError
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.campaign import signature as sig
from astaa_deft.orchestration.campaign.payload import CasePool
from astaa_deft.orchestration.journal.rows import CaseRow
from astaa_deft.orchestration.campaign.known import known_findings
from astaa_deft.orchestration.journal.model import (
    BASELINE, BASELINE_FINDING, CONTROL, MUTATED, BucketSignature, CaseOutcome, CaseStatus, PlannedCase, Timing,
)
from astaa_deft.orchestration.campaign.parts import CampaignParts


HORIZON_SLACK = 1.25  # a mutated case may run this many times the longest clean run (a misled SUT runs longer)


class CampaignStopped(AstaaDeftError):
    """The campaign cannot go on (the SUT does not start): one message, exit 2 (the command adds the fix)."""

    exit_code = 2


LIVE_STEP = 0.5  # s: the measured live time is rounded down to this (same cases for close measurements)


def live_timing(clean: list[CaseOutcome], horizon: float) -> Timing:
    """The anchor channel (its first message came last: every module is running) and the seconds the
    clean runs went on from there (the smallest), from the baseline's clean runs; the horizon without any."""
    anchors = [max(o.first_seen, key=lambda c: (o.first_seen[c], c)) for o in clean if o.first_seen]
    if not anchors:
        return Timing(None, horizon)
    anchor = max(set(anchors), key=lambda c: (anchors.count(c), c))
    lives = [o.seconds - o.first_seen[anchor] for o in clean if anchor in o.first_seen]
    live = max(LIVE_STEP, min(horizon, LIVE_STEP * int(min(lives) / LIVE_STEP)))
    return Timing(anchor, live)


SHUTDOWN_HEADROOM = 2.0  # a learned shutdown delay: the longest a clean run took × this …
SHUTDOWN_SLACK = 0.5  # … + this many seconds (a loaded machine stretches a module's exit: a sleep, Zenoh's close)
# The baseline's own runs date their end with this delay (nothing is learned yet): an exit up to this long after
# the module's last message is its shutdown; one later ends the run at the exit (a silence the run judges), and
# no learned delay exceeds it, so the baseline and every later run date their ends alike.
LEARNING_SHUTDOWN_DELAY = 10.0


def learning_shutdown_delays(spec: Spec) -> dict[str, float]:
    """The shutdown delay of each module whose exit ends the run, for the baseline's runs (they learn it)."""
    section = spec.run
    return {end.module: LEARNING_SHUTDOWN_DELAY for end in section.module_exits} if section is not None else {}


def learned_shutdown_delays(clean: list[CaseOutcome]) -> dict[str, float]:
    """Per module whose exit ends the run: the seconds its exit may come after its last message — the longest
    the clean runs showed (within LEARNING_SHUTDOWN_DELAY: a longer one was a silence), with headroom, at least
    the session's default grace and at most LEARNING_SHUTDOWN_DELAY."""
    seen: dict[str, float] = {}
    for outcome in clean:
        for module, seconds in outcome.shutdowns.items():
            if seconds <= LEARNING_SHUTDOWN_DELAY:
                seen[module] = max(seen.get(module, 0.0), seconds)
    default = SHUTDOWN_GRACE_NS / 1e9
    return {module: round(min(LEARNING_SHUTDOWN_DELAY, max(default, longest * SHUTDOWN_HEADROOM + SHUTDOWN_SLACK)), 1)
            for module, longest in sorted(seen.items())}


def derived_horizon(clean: list[CaseOutcome], cap: float) -> float:
    """Seconds a case may last, from the clean runs: the longest × HORIZON_SLACK, at most ``cap`` (the clean
    runs' own bound); ``cap`` without any finished clean run."""
    seconds = [o.seconds for o in clean if o.status == CaseStatus.DONE and o.seconds > 0]
    if not seconds:
        return cap
    return round(min(cap, max(seconds) * HORIZON_SLACK), 1)


class Baseline(CampaignParts):
    """Clean runs and what they say: horizon, live timing, known baseline findings."""

    # -- baseline: clean runs of every param value, the runs at once, the live time, known findings -------------
    def _baseline(self, pool: CasePool) -> None:
        per_value = max(1, self.config.baseline_runs)
        self._plan_baseline(per_value * len(self.grid))
        stored = self.journal.meta().workers
        if self.calibrated and stored is None:
            self._calibrate_workers(pool, per_value)
        else:
            if self.calibrated and stored is not None:  # resumed: as calibrated then
                self.workers = int(stored)
            self._run_pending_baseline(pool)
        rows = self.journal.cases(BASELINE)
        outcomes = [self.journal.outcome(r) for r in rows]
        failed = [o for o in outcomes if o is not None and o.status == CaseStatus.ERROR]
        if rows and len(failed) == len(rows):
            raise CampaignStopped(f"the SUT does not start: {failed[0].error or failed[0].summary}")
        # Runs of a batch whose timing drifted (too many at once) measured the campaign's load, not the SUT:
        # neither its live time nor its baseline findings.
        overloaded_runs = set(self.journal.meta().overloaded_runs)
        clean = [o for r, o in zip(rows, outcomes, strict=False)
                 if o is not None and o.status == CaseStatus.DONE and r.case_id not in overloaded_runs]
        self._derive_horizon(clean)
        self._calibrate(clean)
        self._learn_shutdown_delays(clean)
        self._file_baseline(rows, outcomes, overloaded_runs)
        self._solo = self._solo_runs()
        for row, outcome in zip(rows, outcomes, strict=False):
            if outcome is not None:
                self.strategy.observe_baseline(row.case_id, outcome)
        self._clean = clean + self._clean_failures_since_baseline()
        self.known = known_findings(self._clean)
        for name, finding in self.known.items():
            self.say(f"baseline finding: '{name}' breaks without mutation ({finding.rate} clean runs): from now on"
                     f" it counts in a case only where the case makes it worse (earlier, more often)")

    def _derive_horizon(self, clean: list[CaseOutcome]) -> None:
        """The cases' horizon from the clean runs (unless --horizon gave one): they ran to the scenario's end."""
        if self.config.horizon is not None:
            return
        self.horizon = derived_horizon(clean, self.clean_horizon)
        self.journal.set_meta(horizon=self.horizon)
        longest = max((o.seconds for o in clean), default=0.0)
        why = (f"the longest clean run took {longest:.1f} s to the scenario's end, × {HORIZON_SLACK:g}" if clean
               else "no clean run finished")
        self.journal.note("horizon", f"cases run at most {self.horizon:g} s: {why}; clean runs at most"
                                     f" {self.clean_horizon:g} s")
        self.say(f"baseline: cases run at most {self.horizon:g} s ({why})")

    def _learn_shutdown_delays(self, clean: list[CaseOutcome]) -> None:
        """Every later run dates its end by each ending module's shutdown delay as the clean runs showed it
        (recomputed on resume from the same journal rows: the same delays)."""
        self.shutdown_delays = learned_shutdown_delays(clean)
        for module, seconds in self.shutdown_delays.items():
            longest = max(seconds for o in clean for m, seconds in o.shutdowns.items()
                          if m == module and seconds <= LEARNING_SHUTDOWN_DELAY)
            self.say(f"baseline: '{module}' exits up to {longest:.2f} s after its last message: a run's end is"
                     f" dated at that message when its exit comes within {seconds:g} s of it")

    def _file_baseline(self, rows: list[CaseRow], outcomes: list[CaseOutcome | None],
                       overloaded_runs: set[str]) -> None:
        """Failing baseline runs into baseline-finding buckets — except runs of a batch that overloaded the
        machine (their failures are the campaign's doing)."""
        for row, outcome in zip(rows, outcomes, strict=False):
            if outcome is None or not outcome.failed or row.bucket or row.case_id in overloaded_runs:
                continue
            signature = BucketSignature.clean(sig.failure_key(outcome))
            self.journal.file_case(row.case_id, signature,
                                   self._bucket(signature, outcome, row.case_id, BASELINE_FINDING))

    def _plan_baseline(self, count: int) -> None:
        """Baseline runs up to ``count``: run n has the grid's value (n-1) mod its size (every value in turn)."""
        for n in range(1, count + 1):
            params = {**self.grid[(n - 1) % len(self.grid)]}
            self._plan(PlannedCase(case_id=f"b-{n:04d}", kind=BASELINE, number=n, seed=self.config.seed, params=params,
                                   testcase=None, strategy="baseline"))

    def _clean_failures_since_baseline(self) -> list[CaseOutcome]:
        """On resume: failing twins and cases that mutated nothing, as known baseline findings again."""
        out = []
        for row in self.journal.cases():
            if row.kind not in (MUTATED, CONTROL) or row.status != CaseStatus.DONE:
                continue
            outcome = self.journal.outcome(row)
            if outcome is not None and outcome.failed and (row.kind == CONTROL or outcome.mutations == 0):
                out.append(outcome)
        return out

    def _calibrate(self, clean: list[CaseOutcome]) -> None:
        """Tell the strategy when the SUT is live: measured once in the baseline, kept in the journal."""
        stored = self.journal.meta().timing
        timing = stored if stored is not None else live_timing(clean, self.horizon)
        self.journal.set_meta(timing={"anchor": timing.anchor, "live": timing.live})
        self.timing = timing
        self.strategy.calibrate(timing)
        if timing.anchor is not None:
            self.say(f"baseline: the stack is live from the first '{timing.anchor}' message and runs"
                     f" {timing.live:g} s on; generated windows fall inside that")

    def _learn_clean_failure(self, outcome: CaseOutcome) -> None:
        """A clean run failed after the baseline: what it broke is a known baseline finding from now on."""
        self._clean.append(outcome)
        before = set(self.known)
        self.known = known_findings(self._clean)
        for name in sorted(set(self.known) - before):
            self.say(f"baseline finding: '{name}' broke in a run without mutation: from now on it counts in a case"
                     f" only where the case makes it worse")

