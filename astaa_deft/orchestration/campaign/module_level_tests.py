"""The DeFT module test of a module-level finding: the failing replay, as a pytest file, and its check.

The test rebuilds the module's frames from the clean baseline log, replays
the module under the finding's fault and asserts the replay no longer fails:
it fails while the module fails under that fault (on the run it came from,
as the campaign checks with one pytest run over every finding's test) and
passes once the module handles the fault. The spec and the log are the
campaign's own (the user's spec file, the baseline's log); every text from
them enters the file as a Python literal.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

from astaa_deft.analysis.deft.module_search import ModuleVerdict
from astaa_deft.engine.bus import process_launch
from astaa_deft.io.output_place import write_atomic

TEST_PREFIX = "test_module_level_"  # + the finding's name: one module name per test file
CHECK_TIMEOUT = 900.0

_TEMPLATE = '''"""DeFT module test of a module-level finding: the module (MODULE) replayed on its frames from a
clean run under one fault. It fails while the module fails under the fault, and passes once the module handles it."""

import json
from pathlib import Path

from astaa_deft.analysis.deft.module_search import ModuleBench
from astaa_deft.analysis.deft.planner_section import replay_module_of
from astaa_deft.analysis.deft.stream_faults import StreamFault
from astaa_deft.analysis.deft.workflow import run_params
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.io.log.reader import read_log
from astaa_deft.io.statefile import StateReader

SPEC = {spec!r}
LOG = {log!r}
MODULE = {module!r}
FAULT = json.loads({fault!r})
FAILED_AS = {signature!r}  # how the replay failed when the campaign found it


def test_module_handles_the_fault():
    spec = load_spec(Path(SPEC))
    log = read_log(Path(LOG))
    bench = ModuleBench(spec, replay_module_of(spec, MODULE), log, run_params(log, spec))
    verdict = bench.run(StreamFault.from_json(StateReader(__file__, FAULT, "export the module-level tests again",
                                                          field="FAULT")))
    assert verdict.applicable, verdict.detail
    assert not verdict.failed, (f"{{MODULE}} under {{verdict.fault.describe()}}: {{verdict.signature}}:"
                                f" {{verdict.detail}}")
'''


def write_test(folder: Path, *, spec_path: Path, log_path: Path, verdict: ModuleVerdict) -> Path:
    """Write the finding's test file into ``folder``; its path."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{TEST_PREFIX}{folder.name}.py"
    write_atomic(path, _TEMPLATE.format(module=verdict.module, spec=str(spec_path), log=str(log_path),
                                        fault=json.dumps(verdict.fault.to_json()), signature=verdict.signature))
    return path


_RESULT = re.compile(r"^(PASSED|FAILED|ERROR) (?:\S+/)?" + re.escape(TEST_PREFIX) + r"(\w+)\.py::")


def check_tests(tests_dir: Path, timeout: float = CHECK_TIMEOUT) -> dict[str, bool]:
    """Run every finding's test once (one pytest): finding name → its test fails (as it should), for each
    test that ran."""
    tests_dir = tests_dir.resolve()  # pytest runs from inside it
    try:
        done = process_launch.run([sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider",
                                   "--rootdir", str(tests_dir), str(tests_dir)], timeout=timeout, cwd=str(tests_dir))
    except subprocess.TimeoutExpired:
        return {}
    found: dict[str, bool] = {}
    for line in (done.stdout + done.stderr).splitlines():
        match = _RESULT.match(line.strip())
        if match:
            found[match.group(2)] = match.group(1) == "FAILED"
    return found
