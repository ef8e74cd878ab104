"""``astaa-deft export DIR -o regress/``: a campaign's findings as a pytest suite for the stack's own CI.

For every confirmed bucket (kind bug, not merged, not one where the fault
alone breaks the invariant through a plant): its minimal test case
(or its first failing one) under ``cases/``, one live test in
``test_live.py`` named ``test_<bucket>_<culprit>`` (marked ``live``), and
its DeFT module tests under ``module/<bucket>_<culprit>/`` (their oracle
tests, marked ``module``); ``regress.json`` (the spec's path, each bucket's
failure, params, the campaign's horizon, settle time and known baseline
findings), a copy of the spec, a ``conftest.py`` and ``pytest.ini`` that
hand the run to :mod:`.regress`, and a README. ``pytest regress/`` runs it
where the stack and astaa-deft are installed; ``-m module`` the fast set,
``-m live`` the live one; ``--param KEY=VALUE`` overrides params.
Everything is written through :mod:`astaa_deft.io.output_place`.
"""

from __future__ import annotations

import ast
import contextlib
import hashlib
import json
import os
import re
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

from astaa_deft.engine.bus import process_launch
from astaa_deft.io.output_place import OutputError, Place, ready_dir, subdir_inside, write_atomic, writing
from astaa_deft.model.data_names import python_name
from astaa_deft.model.errors import Problem
from astaa_deft.orchestration.journal.rows import MUTATED_VALUE
from astaa_deft.orchestration.campaign.campaign import DEFAULT_SETTLE, culprit_family
from astaa_deft.orchestration.campaign.standing import FAULT_ALONE_WHY
from astaa_deft.orchestration.verify.regress import MANIFEST, MARKERS
from astaa_deft.orchestration.verify.campaign_files import copy_module_suite, has_oracles
from astaa_deft.orchestration.verify.workflow import CampaignFindings, targets

SPEC_COPY = "spec.yaml"


@dataclass(frozen=True)
class ExportedBucket:
    bucket: str
    name: str  # <bucket>_<culprit>: the live test's and the module folder's name
    module_tests: bool  # the suite holds oracle tests of it


@dataclass(frozen=True)
class ExportReport:
    out: Path
    buckets: list[ExportedBucket]
    skipped: list[str]


@dataclass(frozen=True, kw_only=True)
class SuiteCheck:
    """The exported suite run once on the stack the campaign ran (its params): each test must fail there."""

    selection: str  # the pytest -m expression run ("module", or "" for every test)
    failed: list[str]  # test ids that failed, as they should
    passed: list[str]  # test ids that passed on the buggy stack: they would not catch their bug
    detail: str  # pytest's last line

    errors: list[str] = field(default_factory=list)  # test ids that errored (collection, setup): neither way

    @property
    def holds(self) -> bool:
        """Every test ran and failed, as it should on the campaign's stack."""
        return bool(self.failed) and not self.passed and not self.errors


def check_suite(out: Path, selection: str = "module", timeout: float = 3600.0) -> SuiteCheck:
    """Run the suite in ``out`` once with the campaign's params (``selection``: a pytest -m expression, "" all):
    which tests fail — as every one should while the bugs are there — and which pass. A test that errors (its
    setup or collection broke) neither failed nor passed: the check does not hold then (``errors``)."""
    args = [sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider", str(out.resolve())]
    if selection:
        args += ["-m", selection]
    try:
        done = process_launch.run(args, timeout=timeout, cwd=str(out.resolve()))
    except subprocess.TimeoutExpired:
        return SuiteCheck(selection=selection, failed=[], passed=[], detail=f"pytest did not finish in {timeout:.0f} s",
                          errors=["(timeout)"])
    lines = (done.stdout or "").splitlines()
    failed = [line.split()[1] for line in lines if line.startswith("FAILED ") and len(line.split()) > 1]
    passed = [line.split()[1] for line in lines if line.startswith("PASSED ") and len(line.split()) > 1]
    errors = [line.split()[1] for line in lines if line.startswith("ERROR ") and len(line.split()) > 1]
    if done.returncode not in (0, 1) and not errors:
        errors = [f"pytest exit {done.returncode}"]
    return SuiteCheck(selection=selection, failed=failed, passed=passed,
                      detail=(lines[-1] if lines else (done.stderr or "").strip())[:300], errors=errors)


def export_suite(campaign_dir: Path, out: Path, *, spec: Path | None = None,
                 trust_journal_spec: bool = False) -> ExportReport:
    """Write the regression suite of the campaign in ``campaign_dir`` into ``out`` (module doc), for the stack
    ``spec`` describes (the user's; None: the spec the journal names, only with ``trust_journal_spec``).

    InputError: no campaign there, its spec is gone or not trusted, a journal row that is not data the tool
    writes; OutputError: ``out`` cannot take the suite (checked before anything is written: it holds files
    an earlier export did not write, or cannot be written).
    """
    campaign = CampaignFindings.open(campaign_dir, spec=spec, trust_journal_spec=trust_journal_spec,
                                     command="export")
    try:
        chosen, skipped = targets(campaign, (), {})
        place = Place(out, "-o")
        earlier = owned_files(out)  # OutputError when out holds anything an export did not write
        ready_dir(place)
        exported: list[ExportedBucket] = []
        buckets: dict[str, dict[str, object]] = {}
        minimised = campaign.journal.minimisations()
        blames = campaign.journal.blames()
        taken: set[str] = set()
        with writing(place):
            for name in earlier:
                (out / name).unlink(missing_ok=True)
            for folder in sorted({str(Path(n).parent) for n in earlier}, key=len, reverse=True):
                with contextlib.suppress(OSError):  # left when it holds a cache pytest wrote
                    (out / folder).rmdir()
            subdir_inside(out, "cases", option="-o")
            subdir_inside(out, "module", option="-o")
            for target in chosen:
                bucket = target.bucket
                if not bucket.is_bug:
                    skipped.append(f"{bucket.bucket}: {bucket.kind}, not a confirmed bug")
                    continue
                blame = blames.get(bucket.bucket)
                if blame is not None and blame.how == MUTATED_VALUE:  # no module under test to test for it
                    skipped.append(f"{bucket.bucket}: {FAULT_ALONE_WHY}, not a bug of the stack")
                    continue
                m = minimised.get(bucket.bucket)
                name = _test_name(bucket.bucket, culprit_family(m.culprit) if m and m.culprit else bucket.family,
                                  taken)
                write_atomic(out / "cases" / f"{bucket.bucket}.xml", target.testcase_xml)
                module_dir = None
                if target.tests_dir is not None and has_oracles(target.tests_dir):
                    module_dir = f"module/{name}"
                    copy_module_suite(target.tests_dir, out / module_dir, campaign.spec)
                buckets[bucket.bucket] = {"name": name, "testcase": f"cases/{bucket.bucket}.xml",
                                          "params": target.params, "invariant": bucket.invariant,
                                          "module": bucket.module, "verdict": bucket.verdict,
                                          "family": bucket.family, "culprit": m.culprit if m else None,
                                          "module_tests": module_dir, "minimal": target.minimal}
                exported.append(ExportedBucket(bucket.bucket, name, module_dir is not None))
            live = _live_tests(exported)
            _check_generated(live, exported)
            write_atomic(out / SPEC_COPY, campaign.spec_path.read_text())
            write_atomic(out / "conftest.py", CONFTEST)
            write_atomic(out / "pytest.ini", PYTEST_INI)
            write_atomic(out / "test_live.py", live)
            write_atomic(out / "README.md", _readme(campaign.spec_path, exported, skipped))
            manifest = {"written_by": WRITTEN_BY, "campaign": str(campaign_dir.resolve()),
                        "spec": str(campaign.spec_path.resolve()), "spec_copy": SPEC_COPY,
                        "horizon": campaign.horizon, "settle": DEFAULT_SETTLE,
                        "known": {k: v.to_json() for k, v in campaign.known.items()}, "buckets": buckets}
            manifest["files"] = _digests(out)
            write_atomic(out / MANIFEST, json.dumps(manifest, indent=1))
        return ExportReport(out, exported, skipped)
    finally:
        campaign.journal.close()


WRITTEN_BY = "astaa-deft export"
_CACHES = ("__pycache__", ".pytest_cache")  # what running the suite adds: neither export's nor the user's work


def _digests(out: Path) -> dict[str, str]:
    """Every file export wrote under ``out`` (its relative path → SHA-256), caches left out."""
    found: dict[str, str] = {}
    for folder, dirs, files in os.walk(out):
        dirs[:] = sorted(d for d in dirs if d not in _CACHES)
        for name in sorted(files):
            path = Path(folder) / name
            if path.relative_to(out).as_posix() != MANIFEST:
                found[path.relative_to(out).as_posix()] = hashlib.sha256(path.read_bytes()).hexdigest()
    return found


def owned_files(out: Path) -> list[str]:
    """The files an earlier export wrote in ``out`` (relative paths, regress.json last), to be replaced; [] for
    a new or empty folder. OutputError when ``out`` holds anything else: a file it did not write, one changed
    since (a hand edit is the user's), a link — export deletes only its own files."""
    if not out.is_dir() or out.is_symlink() or not any(out.iterdir()):
        return []
    manifest = out / MANIFEST
    listed: dict[str, object] = {}
    try:
        body = json.loads(manifest.read_text()) if manifest.is_file() and not manifest.is_symlink() else None
    except (OSError, ValueError, RecursionError):
        body = None
    if isinstance(body, dict) and body.get("written_by") == WRITTEN_BY and isinstance(body.get("files"), dict):
        listed = body["files"]
    else:
        raise OutputError(Problem(str(out), None, None, "the folder holds files that are not a regression suite "
                                  "astaa-deft export wrote", "give an empty or new folder with -o"))
    foreign: list[str] = []
    for folder, dirs, files in os.walk(out):
        here = Path(folder)
        for d in list(dirs):
            if (here / d).is_symlink():
                foreign.append((here / d).relative_to(out).as_posix())
        dirs[:] = [d for d in dirs if d not in _CACHES and not (here / d).is_symlink()]
        for name in files:
            path = here / name
            rel = path.relative_to(out).as_posix()
            if rel == MANIFEST:
                continue
            digest = listed.get(rel)
            if path.is_symlink() or not path.is_file() or digest != hashlib.sha256(path.read_bytes()).hexdigest():
                foreign.append(rel)
    if foreign:
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise OutputError(Problem(str(out), None, None, f"the folder holds files an earlier export did not write "
                                  f"(or that were changed since): {shown}",
                                  "move them away, or give an empty or new folder with -o"))
    return [*sorted(str(n) for n in listed if (out / str(n)).is_file()), MANIFEST]


def _test_name(bucket: str, culprit: str, taken: set[str]) -> str:
    """``<bucket>_<culprit>`` as a Python identifier's tail and a folder name, unique in the suite."""
    base = f"{python_name(bucket)}_{_slug(culprit)}"
    name, n = base, 1
    while name in taken:
        n += 1
        name = f"{base}_{n}"
    taken.add(name)
    return name


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", text).strip("_")[:60] or "bucket"


def _check_generated(source: str, buckets: list[ExportedBucket]) -> None:
    """The generated test module compiles and defines exactly one test per bucket (a bug of the tool else)."""
    tree = ast.parse(source, "test_live.py")
    defined = [node.name for node in tree.body if isinstance(node, ast.FunctionDef)]
    expected = [f"test_{b.name}" for b in buckets]
    if defined != expected:
        raise AssertionError(f"test_live.py defines {defined}, not {expected}")


CONFTEST = '''\
"""Written by astaa-deft export: hands this suite to astaa-deft (options --param/--spec, markers, module tests)."""

from pathlib import Path

import pytest

from astaa_deft.orchestration.verify import regress

HERE = Path(__file__).parent


def pytest_addoption(parser):
    regress.add_options(parser)


def pytest_configure(config):
    regress.configure(config)


def pytest_collection_modifyitems(config, items):
    regress.mark_and_override(config, items, HERE)


@pytest.fixture(scope="session")
def regress_suite(pytestconfig):
    return regress.suite_of(pytestconfig, HERE)
'''

PYTEST_INI = "# Written by astaa-deft export.\n[pytest]\naddopts =\ntestpaths = .\nmarkers =\n" + "".join(
    f"    {name}: {text}\n" for name, text in MARKERS.items())


def _live_tests(buckets: list[ExportedBucket]) -> str:
    lines = ['"""Written by astaa-deft export: one live test per bucket — its minimal test case through the proxy.',
             "",
             "Each passes when the bucket's invariant holds, and fails while the bug is there.",
             '"""', "", "import pytest", "", "from astaa_deft.orchestration.verify.regress import live_failure", ""]
    for b in buckets:  # b.name is a checked identifier tail (model/data_names.py); journal text only as repr
        lines += ["", "@pytest.mark.live", f"def test_{b.name}(regress_suite, tmp_path):",
                  f"    failure = live_failure(regress_suite, {b.bucket!r}, tmp_path)",
                  f"    assert failure is None, {b.bucket + ' still fails: '!r} + str(failure)", ""]
    return "\n".join(lines)


def _readme(spec: Path, buckets: list[ExportedBucket], skipped: list[str]) -> str:
    rows = "\n".join(f"| `test_live.py::test_{b.name}` | {'`module/' + b.name + '/`' if b.module_tests else '—'} |"
                     for b in buckets) or "| (no confirmed bug) | |"
    left = "\n".join(f"* {line}" for line in skipped) or "* none"
    return f"""# Regression suite (astaa-deft export)

The confirmed bugs of an astaa-deft campaign on `{spec.name}`, as tests for the stack's own CI.
Each test is named after its bucket and culprit; each **fails while its bug is there and passes once
it is fixed**.

```bash
pytest regress/                 # everything
pytest regress/ -m module       # fast: DeFT module tests (the module replayed alone, no bus)
pytest regress/ -m live         # full: each bucket's minimal test case run live through the proxy
pytest regress/ --param defects=off            # override a spec param (as astaa-deft proxy --param)
pytest regress/ --spec /path/to/sut.yaml       # the stack's spec on this machine
```

Needs the stack and astaa-deft installed, nothing else. The spec is the campaign's (`regress.json`
names where it was; `spec.yaml` is a copy, used when that path does not exist here — its relative
paths then start at this folder, so give `--spec` where they matter).

| live test | module tests |
|---|---|
{rows}

Module tests keep each DeFT suite's *oracle* tests (the replayed module breaks the bucket's invariant);
its frame-by-frame comparisons with the recorded (buggy) outputs are left out, since a fix changes those
too. A live run not observed to its end fails its test (no verdict is given about it).

Not exported:

{left}
"""
