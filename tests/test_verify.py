"""`astaa-deft verify`: a campaign's buckets against the stack as it is now (real runs of tests/sut/steady.yaml).

The steady stack's worker crashes on a NaN on 'aux' while its param crash_on_nan is 1 (the seeded defect);
a campaign of one test case (a NaN on 'aux') files that crash as a bug. Verified with crash_on_nan=0 the
bucket is fixed (exit 0); with crash_on_nan=1 it still fails (exit 1). The classification and the history
are pure logic, tested apart.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest

from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignConfig
from astaa_deft.orchestration.journal.journal import Journal, open_existing
from astaa_deft.orchestration.journal.model import CaseOutcome, Finding
from astaa_deft.engine.intercept.testcase import parse_testcase
from astaa_deft.orchestration.campaign.strategies.base import Proposal, Strategy
from astaa_deft.orchestration.verify.bisect import search
from astaa_deft.orchestration.campaign.report import write_report
from astaa_deft.orchestration.journal.verifications import record as record_check
from astaa_deft.orchestration.journal.history import fixed_buckets, history
from astaa_deft.orchestration.journal.checks import (
    BucketCheck, FailureWay, Tally, VerifyStatus, classify, failure_keys,
)
from astaa_deft.orchestration.journal.verifications import VerificationRow, verifications

SUT = Path(__file__).parent / "sut"
STEADY = SUT / "steady.yaml"
SET_AUX = ('<testcase id="t" seed="1"><description>x</description><policy id="p1"><channel>aux</channel>'
           '<window from="0.2" to="30"><after channel="aux" message="1"/></window><select limit="1"/>'
           '<set><field path="value" value="dict:float.nan"/></set></policy></testcase>')


class Fixed(Strategy):
    """Proposes the given test cases in order (the campaign's strategy interface; nothing mocked)."""

    name = "fixed"

    def __init__(self, cases: list[str]):
        self.cases = cases

    def propose(self, number: int) -> Proposal:
        return Proposal(parse_testcase(self.cases[number - 1].encode()))  # the campaign holds an object


def run_campaign(out: Path, spec: Path, params: dict[str, list[str]], cases: list[str] | None = None,
                 resume: bool = False, horizon: float = 3.0, minimise: bool = False) -> list[str]:
    """A campaign of the given test cases (default: one NaN on 'aux'); what it said."""
    cases = cases or [SET_AUX]
    journal = Journal(out)
    said: list[str] = []
    try:
        config = CampaignConfig(spec_path=spec, out=out, cases=len(cases), workers=2, horizon=horizon, settle=2.0,
                                minimise=minimise, minimise_timeout=240.0, report=False, baseline_runs=1, reruns=1,
                                params=params)
        if resume:
            config = config.resuming(journal.meta())
        run = Campaign(config, journal, say=said.append)
        run.strategy = Fixed(cases)  # type: ignore[assignment]
        run.run()
    finally:
        journal.close()
    return said


def verify(*args: str, spec: Path = STEADY) -> subprocess.CompletedProcess:
    """``astaa-deft verify ARGS --spec SPEC``: the user names the stack's spec (a campaign folder is data)."""
    return subprocess.run([sys.executable, "-m", "astaa_deft.cli", "verify", *args, "--spec", str(spec)],
                          capture_output=True, text=True, timeout=240)


@pytest.fixture(scope="module")
def steady_campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("verify") / "campaign"
    run_campaign(out, STEADY, {"crash_on_nan": ["1"]})
    return out


def test_verify_says_fixed_when_the_defect_is_off_and_still_failing_when_it_is_on(steady_campaign: Path):
    journal = open_existing(steady_campaign)
    try:
        [bucket] = journal.buckets()
        assert bucket.kind == "bug" and bucket.family == "aux:value:set", bucket
    finally:
        journal.close()
    fixed = verify(str(steady_campaign), "--param", "crash_on_nan=0", "--runs", "1", "--label", "v2")
    assert fixed.returncode == 0, fixed.stdout + fixed.stderr
    assert "B001 fixed: 0/1" in fixed.stdout and "1/1 bucket(s) fixed" in fixed.stdout, fixed.stdout
    failing = verify(str(steady_campaign), "--param", "crash_on_nan=1", "--runs", "1", "--label", "v3",
                     "--bucket", "B001")
    assert failing.returncode == 1, failing.stdout + failing.stderr
    assert "B001 still failing: 1/1" in failing.stdout and "unmutated twins 0/1" in failing.stdout, failing.stdout
    journal = open_existing(steady_campaign)
    try:
        rows = verifications(journal)
    finally:
        journal.close()
    assert [(r.bucket, r.revision, r.status) for r in rows] == [("B001", "v2", "fixed"),
                                                                ("B001", "v3", "still failing")]
    seen = history("B001", rows)
    assert seen.fixed_on is None and seen.reopened_on == ("v3",) and seen.latest is rows[-1]
    status = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "fuzz", "--status", "-o", str(steady_campaign)],
                            capture_output=True, text=True, timeout=60)
    assert "reopened on v3" in status.stdout, status.stdout
    page = write_report(steady_campaign).read_text()
    assert "<h2>Verification</h2>" in page and "reopened on v3" in page and "v2: fixed (0/1)" in page


def test_a_resumed_campaign_reopens_a_bucket_verified_fixed_when_a_case_fails_its_way_again(
        steady_campaign: Path):
    journal = open_existing(steady_campaign)
    try:  # as `verify --label v4` records it, without its runs
        record_check(journal,
            BucketCheck(bucket="B001", revision="v4", status=VerifyStatus.FIXED, reruns=Tally(runs=1),
                        twins=Tally(runs=1), module_tests=None, module_detail="", params={}, minimal=False))
        assert fixed_buckets(verifications(journal)) == {"B001"}
    finally:
        journal.close()
    said = run_campaign(steady_campaign, STEADY, {"crash_on_nan": ["1"]}, cases=[SET_AUX, SET_AUX], resume=True)
    assert any("B001 verified fixed: skipped" in line for line in said), said
    assert any("B001 was verified fixed and reappeared in c-000002" in line for line in said), said
    journal = open_existing(steady_campaign)
    try:
        rows = verifications(journal)
    finally:
        journal.close()
    assert [(r.revision, r.status) for r in rows][-2:] == [("v4", "fixed"), ("(campaign)", "reappeared")]
    assert history("B001", rows).reopened_on[-1] == "(campaign)" and not fixed_buckets(rows)


def test_verify_refuses_an_unknown_bucket_and_a_param_the_spec_does_not_have(steady_campaign: Path):
    done = verify(str(steady_campaign), "--bucket", "B042", "--label", "x")
    assert done.returncode == 2 and "no bucket B042" in done.stderr and "B001" in done.stderr, done.stderr
    done = verify(str(steady_campaign), "--param", "nope=1", "--label", "x")
    assert done.returncode == 2 and "nope" in done.stderr, done.stderr



def test_export_refuses_a_folder_holding_other_files(steady_campaign: Path, tmp_path: Path):
    (tmp_path / "notes.txt").write_text("mine")
    done = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "export", str(steady_campaign), "-o",
                           str(tmp_path), "--spec", str(STEADY)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 4 and "not a regression suite" in done.stderr, done.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]


def outcome(*findings: tuple[str, str | None], status: str = "done") -> CaseOutcome:
    found = [Finding(invariant=inv, crash="Abort", module=module, channel=None, detail="") for inv, module in findings]
    return CaseOutcome(status=status, verdict="Abort" if found else ("Pass" if status == "done" else "?"), summary="s",
                       findings=found)


def test_classification_fixed_still_failing_changed_flaky_not_observed():
    way = FailureWay("(module exit)", "worker")
    same, other, clean, lost = (outcome(("(module exit)", "worker")), outcome(("data_small", "listener")),
                                outcome(), outcome(status="error"))
    assert classify(Tally.of([clean, clean], way), Tally.of([clean, clean], way)) == VerifyStatus.FIXED
    assert classify(Tally.of([same, clean], way), Tally.of([clean, clean], way)) == VerifyStatus.STILL_FAILING
    assert classify(Tally.of([other, clean], way), Tally.of([clean, clean], way)) == VerifyStatus.CHANGED
    assert classify(Tally.of([same, same], way), Tally.of([same, clean], way)) == VerifyStatus.FLAKY
    assert classify(Tally.of([clean, lost], way), Tally.of([clean, clean], way)) == VerifyStatus.NOT_OBSERVED
    assert Tally.of([same, clean, other], way) == Tally(runs=3, same=1, other=1, unobserved=0, other_how="s")
    # another failure the unmutated twins show too (load, the stack's own flakiness) is not a change
    background = failure_keys(other)
    assert classify(Tally.of([other, clean], way, background), Tally.of([other, clean], way)) == VerifyStatus.FIXED


def row(revision: str, status: VerifyStatus) -> VerificationRow:
    return VerificationRow(bucket="B001", revision=revision, status=status, failing=0, runs=1, twin_failures=0, twins=1,
                           module_tests=None, detail="", at=0.0)


def test_history_found_fixed_reopened():
    rows = [row("v1", VerifyStatus.STILL_FAILING), row("v2", VerifyStatus.FIXED), row("v3", VerifyStatus.FIXED)]
    assert history("B001", rows).fixed_on == "v2"
    rows += [row("v4", VerifyStatus.CHANGED), row("v5", VerifyStatus.NOT_OBSERVED), row("v6", VerifyStatus.FIXED)]
    seen = history("B001", rows)
    assert (seen.failing_on, seen.reopened_on, seen.fixed_on) == (("v1", "v4"), ("v4",), "v6")
    assert "reopened on v4" in seen.describe() and "fixed on v6" in seen.describe()


@pytest.mark.parametrize("n", [1, 2, 3, 7, 8, 13])
def test_bisect_search_finds_every_change_in_log2_n_plus_one_verifies(n: int):
    for k in range(1, n + 1):  # revisions 0 (GOOD) … n (BAD); revision k is the first that differs
        asked: list[int] = []

        def fails(index: int, asked: list[int] = asked, k: int = k) -> bool:
            asked.append(index)
            return index < k

        found = search(n, fails)
        assert found.first == k, (n, k)
        assert len(asked) <= math.ceil(math.log2(n)) + 1 + (k == n), (n, k, asked)
        assert len(set(asked)) == len(asked)


@pytest.mark.slow
@pytest.mark.promise
def test_export_writes_a_suite_that_fails_while_the_bug_is_there_and_passes_once_fixed(steady_campaign: Path,
                                                                                       tmp_path: Path):
    regress = tmp_path / "regress"
    done = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "export", str(steady_campaign), "-o", str(regress),
                           "--spec", str(STEADY)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "test_live.py::test_B001_aux_value_set" in done.stdout
    assert {p.name for p in regress.iterdir()} >= {"README.md", "conftest.py", "pytest.ini", "regress.json",
                                                   "test_live.py", "cases"}

    def pytest_regress(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(regress), *args],
                              capture_output=True, text=True, timeout=240, cwd=tmp_path)

    buggy = pytest_regress("-m", "live")
    assert buggy.returncode == 1 and "FAILED" in buggy.stdout and "test_B001_aux_value_set" in buggy.stdout, \
        buggy.stdout
    fixed = pytest_regress("-m", "live", "--param", "crash_on_nan=0")
    assert fixed.returncode == 0 and "1 passed" in fixed.stdout, fixed.stdout
    # the fast set holds no test of this bucket (its crash has no module replay): nothing to select
    assert pytest_regress("-m", "module").returncode == 5


def git(repo: Path, *args: str) -> str:
    done = subprocess.run(["git", "-C", str(repo), "-c", "user.name=t", "-c", "user.email=t@example.invalid",
                           *args], capture_output=True, text=True, check=True, timeout=60)
    return done.stdout.strip()


@pytest.mark.slow
@pytest.mark.promise
def test_bisect_finds_the_revision_that_fixed_a_seeded_defect_in_log2_n_plus_one_verifies(tmp_path: Path):
    # A git repository of the steady stack (its spec names it as 'source: .'): revision 0 crashes on a NaN,
    # revision FIX guards it, the others change nothing that matters.
    repo, n, fix = tmp_path / "stack", 8, 5
    repo.mkdir()
    for name in ("talker.py", "listener.py", "steady_worker.py"):
        (repo / name).write_text((SUT / name).read_text())
    (repo / "steady.yaml").write_text(STEADY.read_text() + "source: .\n")
    git(repo, "init", "-q")
    git(repo, "add", ".")
    git(repo, "commit", "-qm", "r0")
    revisions = [git(repo, "rev-parse", "HEAD")]
    for k in range(1, n + 1):
        if k == fix:
            worker = repo / "steady_worker.py"
            worker.write_text(worker.read_text().replace('crash_on_nan = args.crash_on_nan == "1"',
                                                         "crash_on_nan = False  # fixed: a NaN is ignored"))
        else:
            (repo / "NOTES").write_text(f"revision {k}\n")
        git(repo, "add", ".")
        git(repo, "commit", "-qm", f"r{k}")
        revisions.append(git(repo, "rev-parse", "HEAD"))
    git(repo, "checkout", "-q", revisions[0])
    out = tmp_path / "campaign"
    run_campaign(out, repo / "steady.yaml", {"crash_on_nan": ["1"]})
    git(repo, "checkout", "-q", "master" if git(repo, "branch", "--list", "master") else "main")
    done = verify(str(out), "--bisect", f"{revisions[0]}..{revisions[-1]}", "--bucket", "B001", "--runs", "1",
                  "--build", "touch built", spec=repo / "steady.yaml")
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"stops failing (fixed) at {revisions[fix]}" in done.stdout, done.stdout
    verifies = math.ceil(math.log2(n)) + 1
    assert f"({verifies} verifies)" in done.stdout, done.stdout
    journal = open_existing(out)
    try:
        rows = verifications(journal)
    finally:
        journal.close()
    assert len(rows) == verifies and (repo / "built").is_file()
    assert git(repo, "rev-parse", "HEAD") == revisions[-1]  # the checkout is back where it was


def test_the_spec_names_the_stacks_checkout_in_source(tmp_path: Path):
    from astaa_deft.engine.spec.loader import load_spec
    from astaa_deft.model.errors import InputError

    spec = tmp_path / "sut.yaml"
    spec.write_text(STEADY.read_text() + "source: ../stack\n")
    assert load_spec(spec).source == tmp_path / "../stack"
    assert load_spec(STEADY).source is None
    spec.write_text(STEADY.read_text() + "source: [a]\n")
    with pytest.raises(InputError, match="'source' must be a folder path"):
        load_spec(spec)
