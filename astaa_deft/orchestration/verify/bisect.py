"""``verify --bisect GOOD..BAD``: the first revision where a bucket starts or stops failing.

Over the git checkout the spec's ``source:`` names: the revisions of
``git rev-list --first-parent GOOD..BAD`` after GOOD, in order. GOOD is
verified first; then a binary search, each step a ``verify`` of the bucket
(checkout, the user's ``--build`` command, the bucket's runs and twins),
looks for the first revision whose state (failing or fixed) differs from
GOOD's: ⌈log2 n⌉ + 1 verifies for n revisions (one more when the change is
BAD itself, which is then verified too). The checkout must be clean; it is
put back where it was afterwards. Only the command the user named with
``--build`` is run — never one a journal or a log names.
"""

from __future__ import annotations

import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from astaa_deft.engine.bus import process_launch
from astaa_deft.io.output_place import subdir_inside
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.orchestration.journal.checks import FAILING_STATUSES, VerifyStatus
from astaa_deft.orchestration.verify.revision import describe, git
from astaa_deft.orchestration.verify.workflow import (
    CampaignFindings, VerifyOptions, check_options, check_params, targets, verify_targets, VERIFY_DIR, _slug,
)

BUILD_TIMEOUT = 3600.0


@dataclass(frozen=True)
class Search:
    """What a binary search found: the first index whose state differs from index 0's (None: none does)."""

    first: int | None
    reference: bool  # index 0's state (True: failing)
    asked: dict[int, bool] = field(default_factory=dict)  # index → its state, in the order asked


def search(n: int, fails: Callable[[int], bool]) -> Search:
    """The first of indices 1…n whose ``fails`` differs from index 0's; index 0 asked first (module doc)."""
    asked: dict[int, bool] = {}

    def ask(index: int) -> bool:
        asked[index] = fails(index)
        return asked[index]

    reference = ask(0)
    lo, hi = 0, n
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if ask(mid) == reference:
            lo = mid
        else:
            hi = mid
    if hi not in asked:
        ask(hi)
    return Search(hi if asked[hi] != reference else None, reference, asked)


@dataclass(frozen=True, kw_only=True)
class BisectResult:
    bucket: str
    good: str
    bad: str
    revisions: list[str]  # GOOD, then each revision after it up to BAD (commit hashes)
    found: Search
    names: dict[str, str]  # commit → git describe

    @property
    def first(self) -> str | None:
        return self.revisions[self.found.first] if self.found.first is not None else None

    def describe(self) -> str:
        verifies = len(self.found.asked)
        if self.first is None:
            state = "fails" if self.found.reference else "is fixed"
            return (f"bisect {self.bucket}: it {state} on {self.good} and on every revision checked up to"
                    f" {self.bad}: no change found ({verifies} verifies)")
        how = "stops failing (fixed)" if self.found.reference else "starts failing"
        return (f"bisect {self.bucket}: it {how} at {self.first} ({self.names.get(self.first, '?')}), revision"
                f" {self.found.first} of {len(self.revisions) - 1} after {self.good} ({verifies} verifies)")


def bisect_bucket(options: VerifyOptions, good: str, bad: str, build: str | None,
                  *, say: Callable[[str], None] = print) -> BisectResult:
    """Bisect ``options.buckets[0]`` over GOOD..BAD (module doc). InputError: no ``source:`` in the spec, a
    checkout with changes, revisions git does not know or in the wrong order, a build or a run that fails."""
    [bucket] = options.buckets
    check_options(options)
    first_look = CampaignFindings.open(options.campaign, spec=options.spec,
                                       trust_journal_spec=options.trust_journal_spec, workers=options.workers)
    try:
        checkout = first_look.spec.source
        check_params(first_look.spec, options.params)
        targets(first_look, (bucket,), options.params)  # the bucket exists (InputError if not)
    finally:
        first_look.journal.close()
    if checkout is None:
        raise InputError(Problem(str(first_look.spec_path), None, None, "the spec names no source checkout",
                                 "add 'source: PATH' (the stack's git checkout) to the spec to bisect over it"))
    if git(checkout, "status", "--porcelain", "--untracked-files=no", what="git status"):
        raise InputError(Problem(str(checkout), None, None, "the checkout has uncommitted changes",
                                 "commit or stash them: bisect checks other revisions out there"))
    start = git(checkout, "rev-parse", "--abbrev-ref", "HEAD", what="git rev-parse")
    if start == "HEAD":
        start = git(checkout, "rev-parse", "HEAD", what="git rev-parse")
    good_rev = git(checkout, "rev-parse", "--verify", f"{good}^{{commit}}", what=f"revision {good}")
    git(checkout, "rev-parse", "--verify", f"{bad}^{{commit}}", what=f"revision {bad}")
    after = git(checkout, "rev-list", "--first-parent", "--reverse", f"{good}..{bad}", what="git rev-list").split()
    if not after:
        raise InputError(Problem(str(checkout), None, None, f"no revision after {good} up to {bad}",
                                 "give GOOD..BAD with GOOD an ancestor of BAD"))
    revisions = [good_rev, *after]
    names: dict[str, str] = {}
    say(f"bisect {bucket}: {len(after)} revision(s) after {good} up to {bad} in {checkout}")

    def fails(index: int) -> bool:
        revision = revisions[index]
        git(checkout, "checkout", "--quiet", "--detach", revision, what=f"git checkout {revision[:12]}")
        names[revision] = describe(checkout)
        if build:
            _build(build, checkout, names[revision])
        status = _verify_one(options, names[revision])
        say(f"  {names[revision]}: {status}")
        if status == VerifyStatus.NOT_OBSERVED:
            raise InputError(Problem(str(checkout), None, None, f"{names[revision]}: a run was not observed to its"
                                     " end, so the bucket's state there is unknown",
                                     "make the stack run at that revision, or bisect a narrower range"))
        return status in FAILING_STATUSES

    try:
        found = search(len(after), fails)
    finally:
        git(checkout, "checkout", "--quiet", start, what=f"git checkout {start}")
    return BisectResult(bucket=bucket, good=good, bad=bad, revisions=revisions, found=found, names=names)


def _build(command: str, checkout: Path, revision: str) -> None:
    """Run the user's ``--build`` command in the checkout; InputError when it fails."""
    try:
        done = process_launch.run(["/bin/sh", "-c", command], cwd=str(checkout), timeout=BUILD_TIMEOUT)
    except subprocess.TimeoutExpired:
        raise InputError(Problem("--build", None, None, f"{revision}: '{command}' did not end in"
                                 f" {BUILD_TIMEOUT:.0f} s", "give a build command that ends")) from None
    if done.returncode != 0:
        tail = (done.stderr or done.stdout or "").strip().splitlines()[-1:] or [""]
        raise InputError(Problem("--build", None, None, f"{revision}: '{command}' exited {done.returncode}:"
                                 f" {tail[0][:300]}", "fix the build at that revision, or bisect a narrower range"))


def _verify_one(options: VerifyOptions, revision: str) -> VerifyStatus:
    """One bisect step: verify the bucket against the checkout as it is (its spec read again), journaled."""
    campaign = CampaignFindings.open(options.campaign, spec=options.spec,
                                     trust_journal_spec=options.trust_journal_spec, workers=options.workers)
    try:
        chosen, _ = targets(campaign, options.buckets, options.params)
        out_dir = subdir_inside(options.campaign, VERIFY_DIR,
                                f"bisect-{time.strftime('%Y%m%d-%H%M%S')}-{_slug(revision)}",
                                option="the campaign folder")
        checks = verify_targets(campaign, chosen, options, revision, out_dir=out_dir, say=lambda text: None)
    finally:
        campaign.journal.close()
    return checks[0].status if checks else VerifyStatus.NOT_OBSERVED
