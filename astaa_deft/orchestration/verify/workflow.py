"""``astaa-deft verify DIR``: every bucket of a campaign checked against the stack as it is now.

For each bucket, its minimal test case (or, not minimised, its first
failing test case) runs live N times beside N unmutated twins — the same
spec, params (``--param`` overriding the case's, as in ``proxy``), horizon,
settle time, known baseline findings and runs at once as the campaign's,
through the campaign's own case pool — and its module tests run once with
the same params. ``journal.checks.classify`` decides fixed / still failing / changed /
flaky; each check goes into the journal (``orchestration/journal/verifications.py``) with the stack's
revision. Runs go to ``DIR/verify/<revision>-<time>/``.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.intercept.testcase import TestCase
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.engine.spec.params import check_param_values
from astaa_deft.io.output_place import Place, ready_dir, subdir_inside, writing
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.limits import MAX_PROCESSES
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.campaign import signature as sig
from astaa_deft.orchestration.campaign.baseline import learned_shutdown_delays
from astaa_deft.orchestration.campaign.campaign import DEFAULT_HORIZON, DEFAULT_SETTLE, default_workers
from astaa_deft.orchestration.journal.journal import Journal, open_existing
from astaa_deft.orchestration.campaign.journal_spec import journal_spec
from astaa_deft.orchestration.campaign.known import KnownFinding, judged, known_findings
from astaa_deft.orchestration.journal.model import (
    BASELINE, CONTROL, MUTATED, RERUN, CaseOutcome, CaseStatus, PlannedCase,
)
from astaa_deft.orchestration.campaign.module_tests import is_crash_bucket, run_module_tests
from astaa_deft.orchestration.campaign.payload import CasePayload, read_testcase
from astaa_deft.orchestration.journal.rows import Bucket
from astaa_deft.orchestration.journal import verifications
from astaa_deft.orchestration.verify.campaign_files import copy_module_suite, tests_dir_inside
from astaa_deft.orchestration.journal.checks import (
    FAILING_STATUSES, BucketCheck, FailureWay, Tally, VerifyStatus, classify, failure_keys,
)
from astaa_deft.orchestration.verify.revision import describe

DEFAULT_RUNS = 3
VERIFY_DIR = "verify"
EXIT_NOT_OBSERVED = 3


MAX_LABEL_CHARS = 200  # a revision label (--label, git describe): one line the report shows
MAX_PARAM_CHARS = 10_000  # a --param value: what the journal's reader takes back (checked_rows.MAX_PARAM)


@dataclass(frozen=True, kw_only=True)
class VerifyOptions:
    campaign: Path
    spec: Path | None = None  # the stack's spec: the user's file (None: the one the journal names, if trusted)
    trust_journal_spec: bool = False  # run what the spec the journal names runs (listed when refused)
    params: dict[str, str] = field(default_factory=dict)  # overrides of each case's params
    runs: int = DEFAULT_RUNS  # re-runs of each test case, and as many unmutated twins
    label: str | None = None  # the stack's revision (default: git describe of the spec's source folder)
    buckets: tuple[str, ...] = ()  # () every bucket
    dictionaries: tuple[Path, ...] = ()  # the campaign's extra dictionaries (its test cases may name their values)
    workers: int | None = None  # runs at once (default: the campaign's)
    settle: float = DEFAULT_SETTLE


@dataclass(frozen=True, kw_only=True)
class Target:
    """A bucket to verify: what runs, with which params, and its module tests."""

    bucket: Bucket
    testcase_xml: str
    params: dict[str, str]
    minimal: bool
    tests_dir: Path | None

    @property
    def way(self) -> FailureWay:
        return FailureWay(self.bucket.invariant, self.bucket.module)


@dataclass(frozen=True)
class VerifyReport:
    revision: str
    checks: list[BucketCheck]
    skipped: list[str]  # buckets not verified, each with why
    out_dir: Path

    @property
    def exit_code(self) -> int:
        """0 every bucket verified is fixed; 1 one still fails (any way, or flaky); 3 none fails but a run was not
        observed, or no bucket was verified at all (nothing was seen to be fixed)."""
        statuses = {c.status for c in self.checks}
        if statuses & FAILING_STATUSES:
            return 1
        if VerifyStatus.NOT_OBSERVED in statuses or not self.checks:
            return EXIT_NOT_OBSERVED
        return 0


@dataclass(frozen=True, kw_only=True)
class CampaignFindings:
    """What verify reads of a campaign: its journal, spec, known baseline findings and settings."""

    journal: Journal
    spec_path: Path
    spec: Spec
    known: dict[str, KnownFinding]
    horizon: float
    workers: int
    shutdown_delays: dict[str, float] = field(default_factory=dict)  # learned from the baseline, as the campaign did

    @classmethod
    def open(cls, directory: Path, *, spec: Path | None, trust_journal_spec: bool = False,
             workers: int | None = None, command: str = "verify") -> CampaignFindings:
        """The campaign in ``directory``, run with ``spec`` (the user's), or — only with ``trust_journal_spec``
        — the spec its journal names. InputError when there is no campaign, the spec is gone or bad, or the
        journal's spec would run programs nobody vouched for (the refusal lists them)."""
        journal = open_existing(directory)
        try:
            meta = journal.meta()
            if spec is not None:
                spec_path, loaded = spec, load_spec(spec)
            else:
                spec_path, loaded = journal_spec(journal.path, meta.spec, trusted=trust_journal_spec,
                                                 command=command, why="live runs and module tests")
            return cls(journal=journal, spec_path=spec_path, spec=loaded, known=_known(journal),
                       horizon=meta.horizon or DEFAULT_HORIZON,
                       workers=workers or meta.workers or _ran_at_once(journal) or default_workers(len(loaded.modules)),
                       shutdown_delays=learned_shutdown_delays(_baseline_runs(journal)))
        except BaseException:
            journal.close()
            raise


def _ran_at_once(journal: Journal) -> int | None:
    """The most runs at once the campaign's cases ended at (a campaign given --workers stores no calibration)."""
    counts = [r.at_once for r in journal.cases() if r.at_once]
    return min(max(counts), MAX_PROCESSES) if counts else None


def _baseline_runs(journal: Journal) -> list[CaseOutcome]:
    """The campaign's finished baseline runs (those of an overloaded batch apart): what it learned from."""
    overloaded = set(journal.meta().overloaded_runs)
    return [o for r in journal.cases(BASELINE) if r.status == CaseStatus.DONE and r.case_id not in overloaded
            and (o := r.outcome()) is not None]


def _known(journal: Journal) -> dict[str, KnownFinding]:
    """The campaign's known baseline findings: what its clean runs broke (the campaign's own rule)."""
    overloaded = set(journal.meta().overloaded_runs)
    clean: list[CaseOutcome] = []
    for row in journal.cases():
        outcome = row.outcome()
        if outcome is None or row.status != CaseStatus.DONE or row.case_id in overloaded:
            continue
        if row.kind == BASELINE or (outcome.failed and (row.kind == CONTROL
                                                        or (row.kind == MUTATED and outcome.mutations == 0))):
            clean.append(outcome)
    return known_findings(clean)


def targets(campaign: CampaignFindings, names: tuple[str, ...],
            params: dict[str, str]) -> tuple[list[Target], list[str]]:
    """The buckets to verify (``names``, or every one not merged) and those left out, each with why.
    InputError for a name the campaign has no bucket of."""
    journal = campaign.journal
    every = {b.bucket: b for b in journal.buckets()}
    unknown = [n for n in names if n not in every]
    if unknown:
        raise InputError(Problem(str(journal.path), None, None, f"no bucket {', '.join(unknown)} in this campaign",
                                 f"give one of: {', '.join(every) or '(none: the campaign found nothing)'}"))
    minimised = journal.minimisations()
    checked = journal.module_tests()
    chosen, skipped = [], []
    for bucket in every.values():
        if names and bucket.bucket not in names:
            continue
        if bucket.merged_into is not None:
            skipped.append(f"{bucket.bucket}: merged into {bucket.merged_into}")
            continue
        if bucket.without_mutation:
            skipped.append(f"{bucket.bucket}: fails without mutation (a baseline finding): no test case to verify")
            continue
        m = minimised.get(bucket.bucket)
        first = journal.case(bucket.first_case)
        minimal = m is not None and m.exit_code == 0 and bool(m.minimal_xml)
        xml = m.minimal_xml if minimal and m is not None else (first.testcase_xml if first is not None else None)
        if not xml or first is None:
            skipped.append(f"{bucket.bucket}: the journal holds no test case of it")
            continue
        check_params(campaign.spec, first.params, f"{journal.path}: cases[{first.case_id}].params")
        if m is not None and m.tests_dir:
            tests = tests_dir_inside(journal.path.parent, m.tests_dir, journal=journal.path,
                                     field=f"minimisations[{bucket.bucket}].tests_dir")
        elif bucket.bucket in checked:
            tests = tests_dir_inside(journal.path.parent, checked[bucket.bucket].tests_dir, journal=journal.path,
                                     field=f"module_tests[{bucket.bucket}].tests_dir")
        else:
            tests = None
        chosen.append(Target(bucket=bucket, testcase_xml=xml, params={**first.params, **params}, minimal=minimal,
                             tests_dir=tests))
    return chosen, skipped


def verify_campaign(options: VerifyOptions, say: Callable[[str], None] = print) -> VerifyReport:
    """Verify the campaign in ``options.campaign`` against the stack as it is now (module doc).

    InputError: no campaign there, its spec is gone, a bucket or ``--param`` it does not have, no revision
    to be had from ``source:``; OutputError when the campaign folder cannot take the runs or the journal rows.
    """
    check_options(options)
    campaign = CampaignFindings.open(options.campaign, spec=options.spec,
                                     trust_journal_spec=options.trust_journal_spec, workers=options.workers)
    try:
        check_params(campaign.spec, options.params)
        revision = check_label(options.label or stack_revision(campaign.spec),
                               "--label" if options.label else "git describe")
        chosen, skipped = targets(campaign, options.buckets, options.params)
        place = Place(options.campaign, "the campaign folder")
        ready_dir(place, temp=True)
        with writing(place):
            out_dir = subdir_inside(options.campaign, VERIFY_DIR, f"{time.strftime('%Y%m%d-%H%M%S')}-{_slug(revision)}",
                                    option="the campaign folder")
            checks = verify_targets(campaign, chosen, options, revision, out_dir=out_dir, say=say)
        return VerifyReport(revision, checks, skipped, out_dir)
    finally:
        campaign.journal.close()


def check_options(options: VerifyOptions) -> None:
    """InputError for an option whose value the journal could not take back (checked before any work):
    a ``--param`` value or a ``--label`` longer than the journal's reader reads, a label of many lines."""
    for key, value in options.params.items():
        if len(value) > MAX_PARAM_CHARS:
            raise InputError(Problem("--param", None, None, f"the value of {key[:60]} is {len(value):,} characters "
                                     f"long (at most {MAX_PARAM_CHARS:,})", "give a shorter value"))
    if options.label is not None:
        check_label(options.label, "--label")


def check_label(label: str, where: str) -> str:
    """``label`` when it is one printable line of at most MAX_LABEL_CHARS, else InputError naming ``where``."""
    if not label or len(label) > MAX_LABEL_CHARS or not label.isprintable():
        raise InputError(Problem(where, None, None, f"the revision label {label[:60]!r} is not one line of 1 to "
                                 f"{MAX_LABEL_CHARS} printable characters", "give a short label with --label"))
    return label


def check_params(spec: Spec, params: dict[str, str], where: str = "--param") -> None:
    """InputError for a param (of ``--param``, or of a journal row: ``where``) the spec does not declare, or a
    value outside its declared choices."""
    unknown = sorted(set(params) - set(spec.params))
    if unknown:
        shown = ", ".join(name[:60] for name in unknown[:5])
        raise InputError(Problem(where, None, None, f"the spec declares no param {shown}",
                                 f"give one of: {', '.join(sorted(spec.params)) or '(the spec has no params)'}"))
    check_param_values(spec, {k: [v] for k, v in params.items()}, where)


def stack_revision(spec: Spec) -> str:
    """``git describe`` of the spec's ``source:`` folder; without one, "unlabelled" and the time."""
    if spec.source is not None:
        return describe(spec.source)
    return f"unlabelled {time.strftime('%Y-%m-%d %H:%M:%S')}"


def verify_targets(campaign: CampaignFindings, chosen: list[Target], options: VerifyOptions, revision: str,
                   *, out_dir: Path, say: Callable[[str], None]) -> list[BucketCheck]:
    """Run every target's re-runs and twins (the campaign's pool, its runs at once), then its module tests;
    each check journaled as it is decided."""
    from astaa_deft.orchestration.campaign.executors import LocalPool

    if not chosen:
        return []
    runs = max(1, options.runs)
    say(f"verify: {len(chosen)} bucket(s) on {revision}: {runs} run(s) of each test case beside {runs} unmutated"
        f" twin(s), {campaign.workers} at once")
    payloads: dict[str, tuple[Target, bool]] = {}  # case id → (target, is a re-run)
    dictionary = load_dictionary(list(options.dictionaries))
    testcases = {target.bucket.bucket: read_testcase(target.testcase_xml, f"{campaign.journal.path}:"
                                                     f" {target.bucket.bucket}", campaign.spec, dictionary)
                 for target in chosen}  # the journal's text, checked as a worker checks it
    pool = LocalPool(campaign.workers)
    try:
        for n, target in enumerate(chosen, start=1):
            for k in range(1, runs + 1):
                for rerun in (True, False):
                    case_id = f"{'r' if rerun else 't'}-{target.bucket.bucket}-{k}"
                    case = PlannedCase(case_id=case_id, kind=RERUN if rerun else CONTROL, number=n, seed=0,
                                       params=target.params,
                                       testcase=testcases[target.bucket.bucket] if rerun else None, strategy="verify",
                                       parent=target.bucket.bucket)
                    payload = CasePayload(spec=str(campaign.spec_path.resolve()), case=case,
                                          run_dir=str((out_dir / target.bucket.bucket / case_id).resolve()),
                                          horizon=campaign.horizon,
                                          dictionaries=tuple(str(p.resolve()) for p in options.dictionaries),
                                          settle=options.settle if rerun else None, known=tuple(sorted(campaign.known)),
                                          shutdown_delays=dict(campaign.shutdown_delays))
                    payloads[case_id] = (target, rerun)
                    pool.submit(case_id, payload.to_json())
        outcomes: dict[str, CaseOutcome] = {}
        while pool.pending():
            for case_id, outcome in pool.done(timeout=0.5):
                outcomes[case_id] = outcome
    finally:
        pool.close()
    checks = []
    for target in chosen:
        mine = {cid: o for cid, o in outcomes.items() if payloads[cid][0] is target}
        reruns = [_judged(campaign, o, testcases[target.bucket.bucket]) for cid, o in mine.items() if payloads[cid][1]]
        twins = [_judged(campaign, o, None) for cid, o in mine.items() if not payloads[cid][1]]
        background = frozenset().union(*(failure_keys(o) for o in twins))
        rerun_tally, twin_tally = Tally.of(reruns, target.way, background), Tally.of(twins, target.way)
        module, detail = _module_tests(campaign, target, out_dir, options.params)
        check = BucketCheck(bucket=target.bucket.bucket, revision=revision, status=classify(rerun_tally, twin_tally),
                            reruns=rerun_tally, twins=twin_tally, module_tests=module, module_detail=detail,
                            params=target.params, minimal=target.minimal)
        verifications.record(campaign.journal, check)
        say(f"  {check.describe()}")
        checks.append(check)
    return checks


def _judged(campaign: CampaignFindings, outcome: CaseOutcome, testcase: TestCase | None) -> CaseOutcome:
    """A run as the campaign counts it: self-inflicted findings and known baseline findings no worse apart."""
    if testcase is not None:
        outcome = sig.without_self_inflicted(outcome, testcase, campaign.spec)
    return judged(outcome, campaign.known)


def _module_tests(campaign: CampaignFindings, target: Target, out_dir: Path,
                  params: dict[str, str]) -> tuple[bool | None, str]:
    """Run the bucket's module tests once, with the params overridden: (still fail on the defect?, why)."""
    if target.tests_dir is None:
        return None, ""
    suite = out_dir / target.bucket.bucket / "tests"
    copy_module_suite(target.tests_dir, suite, campaign.spec, params=params)
    bucket = target.bucket
    verdict = run_module_tests(suite, crash=is_crash_bucket(bucket.verdict, bucket.invariant, campaign.spec))
    return verdict.fails_on_defect, verdict.detail


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("_")[:60] or "revision"
