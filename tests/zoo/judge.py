"""What the zoo asks of an extraction, measured on one member's run (used by the tests and the benchmark).

- the outputs reproduced at θ = 0 (as recorded outputs, so a per-trigger
  module's frames answered with nothing do not count) against the floor,
  and the outputs the floor reproduced that extraction did not (``lost``);
- the frames chosen that are the ones the module used (its evaluation
  record, ``debug.inputs``);
- the extracted suite run under pytest (a subprocess, as a user runs it)
  on the very run it came from: every test must pass.
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from astaa_deft.analysis.deft.workflow import ExtractOptions, ExtractReport, extract_module_tests

from zoo.floor import Floor, output_key, plain_replay
from zoo.generate import MODULE, Stack
from zoo.truth import right_frame


@dataclass(frozen=True)
class SuiteRun:
    passed: int
    failed: int  # failed or errored tests
    tests: int  # tests the suite's manifest holds (frames; 0: nothing was written)
    output: str  # pytest's last lines

    @property
    def all_pass(self) -> bool:
        return self.failed == 0 and self.passed == self.tests


@dataclass(frozen=True)
class Extracted:
    outputs: int  # recorded outputs of the module
    exact: int  # recorded outputs reproduced at θ = 0
    reproduced: frozenset[tuple[int, bytes]]  # their identities (floor.output_key)
    right: int  # frames with an output whose inputs are the ones the module used
    frames: int  # frames with an output
    tests: int  # module tests written
    seconds: float  # wall time of the extraction (reading the log, searching, writing the suite)
    report: ExtractReport
    near: int = 0  # recorded outputs reproduced within 1e-9 (θ = 0 included): off by rounding, not by frame


def extract(stack: Stack, log: Path, out_dir: Path, *, jobs: int | None = None) -> Extracted:
    """``astaa-deft extract LOG --spec SPEC --module module --threshold 0 -o out_dir``, as a library call."""
    t0 = time.perf_counter()
    report = extract_module_tests(log, stack.spec_path, out_dir, ExtractOptions(module=MODULE, threshold=0.0,
                                                                                  jobs=jobs))
    seconds = time.perf_counter() - t0
    ex = report.extraction
    answered = [f for f in ex.frames if f.output is not None]
    exact = [f for f in answered if f.comparison.distance == 0.0]
    outputs = ex.recorded_outputs if ex.recorded_outputs is not None else ex.outputs
    right = sum(right_frame(f.output.data, f.inputs) for f in answered if f.output is not None)
    near = sum(1 for f in answered if f.comparison.distance <= 1e-9)
    return Extracted(outputs, len(exact), frozenset(output_key(f.output) for f in exact if f.output is not None),
                     right, len(answered), report.accepted, seconds, report, near)


def lost(floor: Floor, extracted: Extracted, stack: Stack, log: Path) -> int:
    """Outputs the plain replay reproduced and extraction did not (a cut that loses one is a bug)."""
    from astaa_deft.engine.spec.loader import load_spec
    from astaa_deft.io.log.reader import read_log

    spec = load_spec(stack.spec_path)
    outputs = sorted(read_log(log).on(spec.channel("out").key), key=lambda m: m.log_time)
    return sum(1 for ok, m in zip(floor.reproduced, outputs, strict=True)
               if ok and output_key(m) not in extracted.reproduced)


def run_suite(directory: Path, timeout: float = 600.0) -> SuiteRun:
    """``pytest DIR`` in a subprocess: the suite on the run it came from."""
    import json

    manifest = directory / "deft.json"
    # Frames marked "check": false are stepped for the state they build, not tested (docs/deft.md).
    tests = sum(1 for frame in json.loads(manifest.read_text())["frames"] if frame.get("check", True)) \
        if manifest.is_file() else 0
    if tests == 0:
        return SuiteRun(0, 0, 0, "no module tests written")
    res = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:randomly",
                          str(directory)], capture_output=True, text=True, timeout=timeout)
    tail = res.stdout.strip().splitlines()[-1] if res.stdout.strip() else res.stderr[-300:]

    def count(word: str) -> int:
        found = re.search(rf"(\d+) {word}", tail)
        return int(found.group(1)) if found else 0

    return SuiteRun(count("passed"), count("failed") + count("error"), tests, tail)


__all__ = ["Extracted", "SuiteRun", "extract", "lost", "plain_replay", "run_suite"]
