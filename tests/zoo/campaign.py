"""A campaign on a zoo member with a seeded defect, and what it made of each confirmed bucket's module tests.

    found = run_campaign(stack, cases=[nan_case("c")], out=tmp / "campaign")   # the campaign's own machinery
    for bucket in found.replayable():                                           # confirmed, module replayable
        suite = found.suite(bucket)                                             # the journal's module tests
        run_suite(suite)                                                        # pytest in a child: fails?
        run_suite(suite, defect="none")                                         # the same with the defect off

``run_campaign`` runs the real campaign (baseline, cases in worker
processes on Zenoh, re-runs and twins, buckets in SQLite, minimisation in a
child process, the module tests written and run once) with the given test
cases in order — a scripted strategy registered for the run (the random
strategy's first round on a zoo member mutates every channel and field, so
which case hits the seeded defect first is the dictionary's order, not the
test's) — or, with ``cases=None``, with the random strategy, as ``fuzz`` does.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.intercept.testcase import TestCase, parse_testcase
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.model.sut import Spec
from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignConfig
from astaa_deft.orchestration.journal.journal import Bucket, Journal
from astaa_deft.orchestration.journal.rows import ModuleTestsRow
from astaa_deft.orchestration.campaign.strategies.base import STRATEGIES, Proposal, Strategy

from zoo.generate import Stack

SCRIPTED = "zoo-scripted"


def nan_case(channel: str, *, after_s: float = 0.5, value: str = "dict:float.nan") -> bytes:
    """One message of ``channel`` after ``after_s`` s (counted from c's first message, as the campaign's
    windows are) with every value of ``v`` set to ``value``: what the random strategy's boundary probes do."""
    return (f'<testcase id="nan-{channel}" seed="1"><description>{channel}: v[*] = {value}, one message'
            f'</description><policy id="p1"><channel>{channel}</channel><window from="{after_s:g}">'
            f'<after channel="c" message="1"/></window><select limit="1"/>'
            f'<set><field path="v[*]" value="{value}"/></set></policy></testcase>').encode()


class _Scripted(Strategy):
    """The given test cases in order, then the last one again (a campaign asks for as many as ``cases``)."""

    name = SCRIPTED
    script: Sequence[TestCase] = ()

    def __init__(self, spec: Spec, dictionary: object, seed: int, duration: float) -> None:
        self.cases = list(type(self).script)

    def propose(self, number: int) -> Proposal:
        return Proposal(self.cases[min(number - 1, len(self.cases) - 1)])


@dataclass
class CampaignFound:
    """A finished campaign's journal, read once."""

    stack: Stack
    out: Path
    said: list[str]
    buckets: list[Bucket] = field(default_factory=list)
    module_tests: dict[str, ModuleTestsRow] = field(default_factory=dict)
    minimised: dict[str, str] = field(default_factory=dict)  # bucket → minimisation status

    def replayable(self) -> list[Bucket]:
        """The confirmed buckets (merged ones aside) whose failing module the spec can replay alone."""
        spec = load_spec(self.stack.spec_path)
        modules = {entry.module for entry in spec.replay} | (
            {spec.planner.module} if spec.planner is not None else set())
        return [b for b in self.buckets if b.is_bug and b.merged_into is None and b.module in modules]

    def suite(self, bucket: Bucket) -> Path | None:
        row = self.module_tests.get(bucket.bucket)
        return Path(row.tests_dir) if row is not None and row.tests_dir else None


def run_campaign(stack: Stack, out: Path, *, cases: Sequence[bytes] | None, count: int | None = None,
                 **config: object) -> CampaignFound:
    """Run a campaign on ``stack`` into ``out`` (the scripted cases, or the random strategy when None)."""
    spec = load_spec(stack.spec_path)
    said: list[str] = []
    options: dict[str, object] = {"workers": 2, "seed": 1, "baseline_runs": 1, **config}
    if cases is not None:
        dictionary = load_dictionary([])
        _Scripted.script = [parse_testcase(xml, f"scripted-{k}", spec, dictionary) for k, xml in enumerate(cases)]
        STRATEGIES.register(SCRIPTED, _Scripted)
        options["strategy"] = SCRIPTED
    journal = Journal(out)
    try:
        Campaign(CampaignConfig(spec_path=stack.spec_path, out=out, cases=count or len(cases or ()) or 10,
                                **options),  # type: ignore[arg-type]
                 journal, say=said.append).run()
        found = CampaignFound(stack, out, said, journal.buckets(), journal.module_tests(),
                              {name: row.status for name, row in journal.minimisations().items()})
    finally:
        journal.close()
        if cases is not None:
            STRATEGIES.unregister(SCRIPTED)
    return found


@dataclass(frozen=True)
class SuiteRun:
    returncode: int
    output: str

    @property
    def failed(self) -> bool:
        return self.returncode == 1


def run_suite(suite: Path, *, defect: str | None = None, scratch: Path | None = None) -> SuiteRun:
    """pytest on a written suite in a child process, as a user runs it; with ``defect``, on a copy whose
    stored spec gives the module that defect instead (``"none"``: the defect off)."""
    if defect is not None:
        assert scratch is not None, "a copy needs a place"
        copy = scratch / f"{suite.name}-defect-{defect}"
        shutil.rmtree(copy, ignore_errors=True)
        shutil.copytree(suite, copy)
        manifest = json.loads((copy / "deft.json").read_text())
        spec_yaml = manifest["spec_yaml"]
        switched = spec_yaml.replace('"defect": "crash_on_nan"', f'"defect": "{defect}"').replace(
            '"defect": "nan_state"', f'"defect": "{defect}"')
        assert switched != spec_yaml or f'"defect": "{defect}"' in spec_yaml, "the suite's spec names no defect"
        manifest["spec_yaml"] = switched
        (copy / "deft.json").write_text(json.dumps(manifest))
        suite = copy
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rf", "-p", "no:cacheprovider", str(suite)],
                          capture_output=True, text=True, cwd=suite, timeout=600)
    return SuiteRun(done.returncode, done.stdout + done.stderr)
