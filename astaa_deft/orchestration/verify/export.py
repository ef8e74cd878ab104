"""``astaa-deft export DIR -o regress/``: a campaign's findings as a pytest suite for the stack's own CI.

For every confirmed bucket (kind bug, not merged): its minimal test case
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

import json
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from astaa_deft.engine.bus import process_launch
from astaa_deft.io.output_place import OutputError, Place, ready_dir, write_atomic, writing
from astaa_deft.model.errors import Problem
from astaa_deft.orchestration.campaign.campaign import DEFAULT_SETTLE, culprit_family
from astaa_deft.orchestration.verify.regress import MANIFEST, MARKERS
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


@dataclass(frozen=True)
class SuiteCheck:
    """The exported suite run once on the stack the campaign ran (its params): each test must fail there."""

    selection: str  # the pytest -m expression run ("module", or "" for every test)
    failed: list[str]  # test ids that failed, as they should
    passed: list[str]  # test ids that passed on the buggy stack: they would not catch their bug
    detail: str  # pytest's last line

    @property
    def holds(self) -> bool:
        return not self.passed


def check_suite(out: Path, selection: str = "module", timeout: float = 3600.0) -> SuiteCheck:
    """Run the suite in ``out`` once with the campaign's params (``selection``: a pytest -m expression, "" all):
    which tests fail — as every one should while the bugs are there — and which pass."""
    args = [sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider", str(out.resolve())]
    if selection:
        args += ["-m", selection]
    try:
        done = process_launch.run(args, timeout=timeout, cwd=str(out.resolve()))
    except subprocess.TimeoutExpired:
        return SuiteCheck(selection, [], [], f"pytest did not finish in {timeout:.0f} s")
    lines = (done.stdout or "").splitlines()
    failed = [line.split()[1] for line in lines if line.startswith("FAILED ")]
    passed = [line.split()[1] for line in lines if line.startswith("PASSED ")]
    return SuiteCheck(selection, failed, passed, (lines[-1] if lines else (done.stderr or "").strip())[:300])


def export_suite(campaign_dir: Path, out: Path) -> ExportReport:
    """Write the regression suite of the campaign in ``campaign_dir`` into ``out`` (module doc).

    InputError: no campaign there, or its spec is gone; OutputError: ``out`` cannot take the suite (checked
    before anything is written: it holds files that are not an earlier export, or cannot be written).
    """
    campaign = CampaignFindings.open(campaign_dir)
    try:
        chosen, skipped = targets(campaign, (), {})
        place = Place(out, "-o")
        if out.is_dir() and any(out.iterdir()) and not (out / MANIFEST).is_file():
            raise OutputError(Problem(str(out), None, None, "the folder holds files that are not a regression suite",
                                      "give an empty or new folder with -o"))
        ready_dir(place)
        exported: list[ExportedBucket] = []
        buckets: dict[str, dict[str, object]] = {}
        minimised = campaign.journal.minimisations()
        with writing(place):
            for old in ("cases", "module"):
                shutil.rmtree(out / old, ignore_errors=True)
            (out / "cases").mkdir()
            (out / "module").mkdir()
            for target in chosen:
                bucket = target.bucket
                if not bucket.is_bug:
                    skipped.append(f"{bucket.bucket}: {bucket.kind}, not a confirmed bug")
                    continue
                m = minimised.get(bucket.bucket)
                name = f"{bucket.bucket}_{_slug(culprit_family(m.culprit) if m and m.culprit else bucket.family)}"
                write_atomic(out / "cases" / f"{bucket.bucket}.xml", target.testcase_xml)
                module_dir = None
                if target.tests_dir is not None and _has_oracles(target.tests_dir):
                    module_dir = f"module/{name}"
                    shutil.copytree(target.tests_dir, out / module_dir)
                buckets[bucket.bucket] = {"name": name, "testcase": f"cases/{bucket.bucket}.xml",
                                          "params": target.params, "invariant": bucket.invariant,
                                          "module": bucket.module, "verdict": bucket.verdict,
                                          "family": bucket.family, "culprit": m.culprit if m else None,
                                          "module_tests": module_dir, "minimal": target.minimal}
                exported.append(ExportedBucket(bucket.bucket, name, module_dir is not None))
            manifest = {"spec": str(campaign.spec_path.resolve()), "spec_copy": SPEC_COPY,
                        "horizon": campaign.horizon, "settle": DEFAULT_SETTLE,
                        "known": {k: v.to_json() for k, v in campaign.known.items()}, "buckets": buckets}
            write_atomic(out / SPEC_COPY, campaign.spec_path.read_text())
            write_atomic(out / MANIFEST, json.dumps(manifest, indent=1))
            write_atomic(out / "conftest.py", CONFTEST)
            write_atomic(out / "pytest.ini", PYTEST_INI)
            write_atomic(out / "test_live.py", _live_tests(exported))
            write_atomic(out / "README.md", _readme(campaign.spec_path, exported, skipped))
        return ExportReport(out, exported, skipped)
    finally:
        campaign.journal.close()


def _has_oracles(tests_dir: Path) -> bool:
    try:
        manifest = json.loads((tests_dir / "deft.json").read_text())
    except (OSError, ValueError):
        return False
    return bool(manifest.get("oracles"))


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", text).strip("_")[:60] or "bucket"


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
    for b in buckets:
        lines += ["", "@pytest.mark.live", f"def test_{b.name}(regress_suite, tmp_path):",
                  f"    failure = live_failure(regress_suite, {b.bucket!r}, tmp_path)",
                  f"    assert failure is None, f\"{b.bucket} still fails: {{failure}}\"", ""]
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
