"""What an exported regression suite (``astaa-deft export``) runs: its options, markers and live tests.

The suite's generated ``conftest.py`` and ``test_live.py`` call these, so a
suite runs with the astaa-deft installed beside it. A live test runs its
bucket's minimal test case once through the proxy (``runner.run_case``: the
campaign's own run, horizon and settle time) and passes when the bucket's
invariant holds — it fails while the bug is there, and never passes on a run
that was not observed to its end. Module tests are the bucket's DeFT suites
(collected by astaa-deft's pytest plugin), run with the same params.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

from astaa_deft.io.statefile import StateReader, load_json
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.json import JsonObject

if TYPE_CHECKING:
    from astaa_deft.model.sut import Spec

MANIFEST = "regress.json"
LIVE_MARK = "live"
MODULE_MARK = "module"
MARKERS = {MODULE_MARK: "a bucket's DeFT module tests: replays of the module alone, no bus (fast)",
           LIVE_MARK: "a bucket's minimal test case run live through the proxy (the full set)"}
_FIX = "export the suite again (astaa-deft export CAMPAIGN -o DIR): its regress.json is damaged"


@dataclass(frozen=True)
class RegressBucket:
    """One exported bucket as the manifest lists it."""

    testcase: str  # its minimal test case, relative to the suite's folder
    invariant: str
    module: str | None  # the module its finding named (None: none)
    params: dict[str, str]  # the campaign's params it failed with

    @classmethod
    def from_manifest(cls, entry: StateReader) -> RegressBucket:
        """The bucket from its entry in regress.json (InputError naming the field when one is damaged)."""
        testcase, invariant, module, params = entry.fields("testcase", "invariant", "module", "params")
        return cls(testcase.string(), invariant.string(), module.text(optional=True),
                   params.map(lambda value: value.string()))


@dataclass(frozen=True)
class RegressSuite:
    """An exported suite: its folder, its manifest, and the params and spec this pytest run uses."""

    directory: Path
    manifest: JsonObject  # regress.json as export wrote it; each field is checked where it is read
    params: dict[str, str] = field(default_factory=dict)  # --param overrides
    spec: Path | None = None  # --spec: where the stack's spec is on this machine

    @classmethod
    def load(cls, directory: Path, params: dict[str, str] | None = None, spec: Path | None = None) -> RegressSuite:
        """The suite in ``directory``; InputError (naming regress.json) if its manifest is not a JSON object."""
        path = str(directory / MANIFEST)
        manifest = StateReader(path, load_json((directory / MANIFEST).read_bytes(), path, "", _FIX), _FIX)
        return cls(directory, manifest.json_object(), dict(params or {}), spec)

    def _read(self) -> StateReader:
        return StateReader(str(self.directory / MANIFEST), self.manifest, _FIX).obj()

    def spec_path(self) -> Path:
        """--spec, else the campaign's spec where it was, else the copy in the suite."""
        if self.spec is not None:
            return self.spec
        spec, copy = self._read().fields("spec", "spec_copy")
        original = Path(spec.string())
        return original if original.is_file() else self.directory / copy.string()

    @cached_property
    def loaded_spec(self) -> Spec:
        """The spec of :meth:`spec_path`, read once for the pytest session (every bucket's run shares it)."""
        from astaa_deft.engine.spec.loader import load_spec

        return load_spec(self.spec_path())

    def bucket(self, name: str) -> RegressBucket:
        """Bucket ``name`` as the manifest lists it (InputError if it does not, or a field is damaged)."""
        (buckets,) = self._read().fields("buckets")
        return RegressBucket.from_manifest(buckets.obj().get(name).obj())

    def setting(self, name: str) -> float:
        """A number the campaign ran with (``horizon``, ``settle``: seconds)."""
        return self._read().get(name).real()

    def known(self) -> JsonObject:
        """The campaign's known findings, as ``known.from_json`` reads them ({} if none)."""
        (known,) = self._read().fields("known")
        return known.json_object() if known.value is not None else {}

    def params_of(self, name: str) -> dict[str, str]:
        return {**self.bucket(name).params, **self.params}


def live_failure(suite: RegressSuite, name: str, run_dir: Path) -> str | None:
    """Run bucket ``name``'s minimal test case once, live: how it failed its bucket's way (None: it did not).
    Raises AssertionError when the run was not observed to its end (no verdict is given about it)."""
    from astaa_deft.engine.intercept.testcase import load_testcase
    from astaa_deft.orchestration.campaign import signature as sig
    from astaa_deft.orchestration.campaign.known import from_json as known_from_json, judged
    from astaa_deft.orchestration.campaign.runner import CaseLimits, run_case
    from astaa_deft.orchestration.journal.checks import FailureWay

    entry = suite.bucket(name)
    spec = suite.loaded_spec
    testcase = load_testcase(suite.directory / entry.testcase)
    known = known_from_json(suite.known())
    limits = CaseLimits(horizon=suite.setting("horizon"), settle=suite.setting("settle"), known=frozenset(known))
    outcome = run_case(spec, testcase, suite.params_of(name), run_dir, limits=limits)
    if outcome.status != "done":
        raise AssertionError(f"{name}: the run was not observed to its end ({outcome.summary}: {outcome.error})"
                             f" — no verdict; log in {run_dir}")
    outcome = judged(sig.without_self_inflicted(outcome, testcase, spec), known)
    way = FailureWay(entry.invariant, entry.module)
    if way.shown_by(outcome):
        return f"{outcome.summary} (log: {outcome.log_path})"
    return None


def parse_params(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise InputError(Problem("--param", None, None, f"'{item}' is not KEY=VALUE",
                                     "write e.g. --param defects=off"))
        out[key] = value
    return out


# -- the generated conftest.py's hooks ---------------------------------------------------------------------------
def add_options(parser: pytest.Parser) -> None:
    group = parser.getgroup("astaa-deft regression suite")
    group.addoption("--param", action="append", default=[], metavar="KEY=VALUE",
                    help="override a spec param of the live runs and the module replays")
    group.addoption("--spec", type=Path, default=None, help="the stack's spec on this machine")


def configure(config: pytest.Config) -> None:
    for name, text in MARKERS.items():
        config.addinivalue_line("markers", f"{name}: {text}")


def suite_of(config: pytest.Config, directory: Path) -> RegressSuite:
    return RegressSuite.load(directory, parse_params(config.getoption("--param")), config.getoption("--spec"))


def mark_and_override(config: pytest.Config, items: list[pytest.Item], directory: Path) -> None:
    """Keep of each bucket's DeFT suite its oracle tests, marked ``module``, their replays given the run's params.

    Its frame tests compare each replayed output with the recorded one — the
    output of the stack *with* the bug — so a fix changes them too: they say
    that something changed, not whether the bug is gone, and are left out
    (deselected). An oracle test fails while the replayed module breaks the
    bucket's invariant, and passes once it does not.
    """
    suite = suite_of(config, directory)
    kept, dropped = [], []
    for item in items:
        replayed = getattr(item, "suite", None)  # the plugin's FrameTest / OracleTest share their suite
        if replayed is None or directory not in Path(str(item.path)).parents:
            kept.append(item)
            continue
        if not item.name.startswith("oracle_"):
            dropped.append(item)
            continue
        item.add_marker(MODULE_MARK)
        kept.append(item)
        if suite.params:
            replayed.manifest["params"] = {**replayed.manifest.get("params", {}), **suite.params}
    if dropped:
        config.hook.pytest_deselected(items=dropped)
        items[:] = kept
