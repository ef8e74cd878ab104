"""`astaa-deft generate --spec SUT.yaml --count N --seed S -o DIR`: write N test cases."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Sequence

from ..errors import InputError, Problem
from ..intercept.dictionary import load_dictionary
from ..intercept.generate import generate, write_testcases
from ..intercept.testcase import TestCase
from ..spec.loader import load_spec


def run(spec_path: Path, count: int, seed: int, out_dir: Path, duration: float = 30.0,
        include_brittle: bool = False, dictionaries: Sequence[Path] = ()) -> int:
    if count < 1:
        raise InputError(Problem("--count", None, None, f"{count} test cases", "ask for at least 1"))
    if not duration > 0:
        raise InputError(Problem("--duration", None, None, f"{duration} s", "give a positive number of seconds"))
    _check_output_directory(out_dir)
    spec = load_spec(spec_path)
    dictionary = load_dictionary(dictionaries)
    testcases = generate(spec, dictionary, count, seed, duration, include_brittle)
    paths = write_testcases(testcases, out_dir)
    shapes = Counter(_shape(testcase) for testcase in testcases)
    print(f"wrote {len(paths)} test cases to {out_dir} (seed {seed}): {shapes['single']} one field of one "
          f"message, {shapes['multi_field']} several fields of one message, {shapes['repeated']} repeated")
    return 0


def _shape(testcase: TestCase) -> str:
    [policy] = testcase.policies
    if policy.selection.limit is None:
        return "repeated"
    return "multi_field" if len(getattr(policy.action, "fields", ())) > 1 else "single"


def _check_output_directory(out_dir: Path) -> None:
    """Refuse to mix with earlier test cases: a stale tc-0042.xml would be run as if it were new."""
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(Problem(str(out_dir), None, None, "exists and is not a directory",
                                 "give a new or empty directory with -o"))
    existing = sorted(out_dir.glob("tc-*.xml")) if out_dir.is_dir() else []
    if existing:
        raise InputError(Problem(str(out_dir), None, None,
                                 f"already holds {len(existing)} test case file(s), e.g. {existing[0].name}",
                                 "give a new or empty directory with -o, or delete them"))
