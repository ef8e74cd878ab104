"""The campaign's minimisation slots: confirmed buckets minimised alongside the hunt, each in a worker
slot, then the rest after it; DeFT module tests of the module to blame; buckets whose culprits coincide merged.

A part of :class:`~.campaign.Campaign` (its state: :class:`~.parts.CampaignParts`).
"""

from __future__ import annotations

import shutil
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor
from concurrent.futures import wait as futures_wait
from dataclasses import replace
from pathlib import Path

from astaa_deft.orchestration.campaign import signature as sig
from astaa_deft.orchestration.journal.rows import MUTATED_VALUE
from astaa_deft.orchestration.journal.journal import Bucket, Journal
from astaa_deft.orchestration.journal.rows import Minimisation
from astaa_deft.orchestration.campaign.minimiser import MinimiseLimits, Minimised, minimise_run
from astaa_deft.orchestration.campaign.module_tests import (
    TestsVerdict, is_crash_bucket, replayable, run_module_tests,
)
from astaa_deft.orchestration.campaign.planner_tests import build_in_child as build_replay_tests
from astaa_deft.orchestration.campaign.parts import CampaignParts


TESTS_DIR = "tests"
REPLAY_TESTS_SUFFIX = "-replay"  # DeFT replays of the failing run (not the minimiser's failing oracle tests)
MESSAGE_FAULT = "(message fault)"


def merge_same_culprits(journal: Journal) -> list[tuple[str, str]]:
    """Merge each bucket whose minimised culprit is an earlier bucket's: (bucket, merged into) pairs.

    Two signatures can hide one bug (the same NaN breaks two invariants,
    first on one, then on the other; a second field that played no part):
    once minimised, the culprits say so. Culprits coincide when they change
    the same fields of the same channels, whatever the value (``heading =
    max`` and ``heading = big_1e16`` hang the same loop); message faults on
    the same channels (a reorder, a delay) that break the same invariant in
    the same module.
    Only confirmed minimisations count; the earliest bucket keeps the culprit.
    """
    minimised = journal.minimisations()
    owner: dict[str, str] = {}
    merged = []
    for bucket in journal.buckets():
        row = minimised.get(bucket.bucket)
        if not bucket.is_bug or row is None or row.exit_code != 0 or not row.culprit:
            continue
        family = culprit_family(row.culprit)
        if MESSAGE_FAULT in family:  # a reorder and a delay of one channel breaking the same thing: one bug
            family += f" → {bucket.invariant} in {bucket.module}"
        first = owner.setdefault(family, bucket.bucket)
        if first != bucket.bucket and bucket.merged_into != first:
            journal.merge_bucket(bucket.bucket, first)
            merged.append((bucket.bucket, first))
    return merged


def culprit_family(culprit: str) -> str:
    """A minimised culprit without its values, array indices folded; a fault on whole messages (reorder,
    delay, drop, …: no ``field = value``) as ``channel:(message fault)``."""
    parts = set()
    for part in (p.strip() for p in culprit.split(";")):
        if not part:
            continue
        if " = " in part:
            parts.add(sig.fold_indices(part.split(" = ", 1)[0]))
        else:
            parts.add(f"{part.rsplit(':', 1)[0]}:{MESSAGE_FAULT}")
    return "; ".join(sorted(parts))


class MinimisationSlots(CampaignParts):
    """Confirmed buckets minimised in worker slots; module tests; merges."""

    # -- minimisation: confirmed buckets, alongside the hunt, each in a worker slot ---------------------------
    def _start_minimisations(self, hunting: bool) -> None:
        if not self.config.minimise or self.strategy.exports_own_findings:
            return
        done = self.journal.minimisations()
        in_flight = set(self._minimising.values())
        # While hunting, at most half the slots (at least one) minimise: new cases go on in the rest.
        most = max(1, self.workers // 2) if hunting else self.workers
        for bucket in self.journal.buckets(include_merged=False):
            if len(self._minimising) >= most or self._busy() >= self.workers:
                return
            if not bucket.is_bug or bucket.bucket in done or bucket.bucket in in_flight or bucket.bucket in self._fixed:
                continue
            row = self.journal.planned(bucket.first_case)
            if not row.log_path or not Path(row.log_path).is_file():
                continue
            if self._minimiser is None:
                self._minimiser = ThreadPoolExecutor(max_workers=max(self.workers, 1) + 1,
                                                     thread_name_prefix="minimise")
            self.say(f"minimising bucket {bucket.bucket} ({bucket.invariant}) …")
            self.journal.minimisation_started(bucket.bucket)
            future = self._minimiser.submit(self._minimise_one, bucket, Path(row.log_path))
            self._minimising[future] = bucket.bucket

    def _minimise_one(self, bucket: Bucket, log: Path) -> tuple[Minimised, Path | None, TestsVerdict | None]:
        """One bucket's minimisation (a child process, time-boxed), its tests copied and run once on the defect:
        no journal, no output (it runs on a minimisation thread)."""
        out_dir = self.config.out / "minimised" / bucket.bucket
        if out_dir.exists():
            shutil.rmtree(out_dir)
        limits = MinimiseLimits(max_tests=self.config.minimise_max_tests, timeout=self.config.minimise_timeout)
        result = minimise_run(log, self.config.spec_path, out_dir, invariant=bucket.invariant, limits=limits,
                              cancel=self._cancel)
        tests_dir = None
        if result.tests_dir is not None:  # the minimiser's own: they fail on the culprit
            tests_dir = self.config.out / TESTS_DIR / bucket.bucket
            if tests_dir.exists():
                shutil.rmtree(tests_dir)
            shutil.copytree(result.tests_dir, tests_dir)
            verdict = run_module_tests(tests_dir, crash=is_crash_bucket(bucket.verdict, bucket.invariant, self.spec))
            return result, tests_dir, verdict
        return result, None, None

    def _collect_minimisations(self, wait: bool = False) -> None:
        if not self._minimising:
            return
        finished, _ = futures_wait(list(self._minimising), timeout=None if wait else 0,
                                   return_when=FIRST_COMPLETED)
        for future in finished:
            name = self._minimising.pop(future)
            result, tests_dir, verdict = future.result()
            status = "minimised" if result.exit_code == 0 else "not reproduced" if result.exit_code == 1 else "error"
            self.journal.minimised(Minimisation(bucket=name, status=status, exit_code=result.exit_code,
                                                minimal_xml=result.minimal_xml, culprit=result.culprit,
                                                out_dir=str(result.out_dir),
                                                tests_dir=str(tests_dir) if tests_dir else None, seconds=result.seconds,
                                                detail=result.detail))
            self.say(f"  {name} {status}: {result.culprit or '-'} ({result.seconds:.0f} s)")
            self._replay_confirms_blame(name, result)
            if tests_dir is not None and verdict is not None:
                self.say(f"  the minimiser's module tests{self._journal_module_tests(name, tests_dir, verdict)}")

    def _minimise_left(self) -> None:
        """After the hunt: the minimisations still running, then the confirmed buckets none took up, all the
        slots at once; DeFT module tests where the minimiser's are missing or do not fail on the defect;
        buckets whose culprits coincide merged."""
        while True:
            self._collect_minimisations()
            self._start_minimisations(hunting=False)
            if not self._minimising:
                break
            self._collect_minimisations(wait=True)
        minimised = self.journal.minimisations()
        checked = self.journal.module_tests()
        for bucket in self.journal.buckets(include_merged=False):
            row = minimised.get(bucket.bucket)
            module = self._module_to_replay(bucket)
            own = checked.get(bucket.bucket)
            if row is None or module is None or (row.tests_dir and (own is None or own.fails_on_defect is not False)):
                continue  # none to replay, or the minimiser's tests fail on the defect (or could not run)
            log = self.journal.planned(bucket.first_case).log_path
            if log is None:  # minimised from its log, so it has one
                continue
            tests_dir = self._replay_tests(bucket, Path(log), module, fallback=row.tests_dir is not None)
            if tests_dir is not None:
                self.journal.minimised(replace(row, tests_dir=str(tests_dir)))
        for merged, into in merge_same_culprits(self.journal):
            self.say(f"  bucket {merged}: same minimised culprit as {into}: merged")

    def _module_to_replay(self, bucket: Bucket) -> str | None:
        """The module whose DeFT module tests a bucket gets: the module to blame, else the module its finding
        names — when the spec can replay it alone (the planner, a ``replay:`` entry) and it is not the plant;
        None otherwise, and when the blame is the mutated value itself (no module under test mishandled it)."""
        blamed = self.journal.blames().get(bucket.bucket)
        if blamed is not None and blamed.how == MUTATED_VALUE:
            return None
        for module in (blamed.module if blamed is not None else None, bucket.module):
            if replayable(self.spec, module) and not self.spec.is_plant(module):
                return module
        return None

    def _replay_tests(self, bucket: Bucket, log: Path, module: str, *, fallback: bool = False) -> Path | None:
        """DeFT module tests of ``module`` from the bucket's failing run (its frames with the culprit inputs).

        Built in a child process (``planner_tests``: this one runs threads, and
        the replay forks); a crash bucket's suite also gets the frame of the
        cycle the module failed on. The suite is run once and the journal says
        whether it fails on the bucket's defect. ``fallback``: the minimiser's
        tests do not fail on it; these replace them only if they do.
        """
        tests_dir = self.config.out / TESTS_DIR / f"{bucket.bucket}{REPLAY_TESTS_SUFFIX}"
        if tests_dir.exists():
            shutil.rmtree(tests_dir)
        planner = self.spec.planner is not None and self.spec.planner.module == module
        built = build_replay_tests(log, self.config.spec_path, tests_dir, verdict=bucket.verdict,
                                   invariant=bucket.invariant, module=None if planner else module)
        if not built.accepted and not built.failure_frame:
            self.say(f"  {bucket.bucket}: no module tests of {module}: {built.error}")
            shutil.rmtree(tests_dir, ignore_errors=True)
            return None
        if built.failure_frame:
            self.say(f"  + the frame of the cycle {module} failed on")
        crash = is_crash_bucket(bucket.verdict, bucket.invariant, self.spec)
        verdict = run_module_tests(tests_dir, crash=crash)
        if fallback and not verdict.fails_on_defect:
            self.say(f"  {bucket.bucket}: DeFT module tests of {module} do not fail on the defect either "
                     f"({verdict.detail}): the minimiser's stay")
            shutil.rmtree(tests_dir, ignore_errors=True)
            return None
        self.say(f"  {bucket.bucket}: {built.accepted + built.failure_frame} DeFT module test(s) of {module}: "
                 f"pytest {tests_dir}"
                 f"{self._journal_module_tests(bucket.bucket, tests_dir, verdict)}")
        return tests_dir

    def _journal_module_tests(self, bucket: str, tests_dir: Path, verdict: TestsVerdict) -> str:
        """Journal whether a bucket's module tests fail on its defect; a phrase saying so."""
        self.journal.module_tests_checked(bucket, str(tests_dir), verdict.fails_on_defect, verdict.detail)
        how = {True: "they fail on the defect", False: "they do NOT fail on the defect", None: "they could not run"}
        return f"; {how[verdict.fails_on_defect]} ({verdict.detail})"

