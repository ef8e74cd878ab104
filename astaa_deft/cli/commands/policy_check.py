"""`astaa-deft policy check FILE|DIR... [--spec SUT.yaml] [--dictionary FILE]`."""

from __future__ import annotations

import sys
from pathlib import Path
from collections.abc import Sequence

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.engine.intercept.dictionary import load_dictionary
from astaa_deft.engine.intercept.testcase import load_testcase
from astaa_deft.engine.spec.loader import load_spec


def run(files: Sequence[Path], spec_path: Path | None = None, dictionaries: Sequence[Path] = ()) -> int:
    spec = load_spec(spec_path) if spec_path is not None else None
    dictionary = load_dictionary(dictionaries)
    problems: list[Problem] = []
    checked = 0
    for path in _expand(files):
        try:
            testcase = load_testcase(path, spec, dictionary)
        except InputError as exc:
            problems.extend(exc.problems)
            continue
        checked += 1
        actions = ", ".join(sorted({p.action.name for p in testcase.policies}))
        print(f"{path}: ok — test case '{testcase.id}': {len(testcase.policies)} "
              f"polic{'y' if len(testcase.policies) == 1 else 'ies'} ({actions})")
    if spec is None and checked:
        print("note: without --spec, channel, consumer and field names were not checked", file=sys.stderr)
    if problems:
        raise InputError(problems)
    return 0


def _expand(files: Sequence[Path]) -> list[Path]:
    """Files as given; a directory stands for the *.xml files in it."""
    out: list[Path] = []
    for path in files:
        if path.is_dir():
            found = sorted(path.glob("*.xml"))
            if not found:
                raise InputError(Problem(str(path), None, None, "no .xml files in this directory",
                                         "give test case files or a directory holding them"))
            out.extend(found)
        else:
            out.append(path)
    return out
