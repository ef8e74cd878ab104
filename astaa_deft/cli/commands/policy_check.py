"""`astaa-deft policy check FILE|DIR... [--spec SUT.yaml] [--dictionary FILE]`: validate ASTAA test cases.

Exit 0 when every file loads; the problems of all files raise one InputError (exit 2, printed by the CLI).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.model.errors import InputError, Problem

if TYPE_CHECKING:
    from astaa_deft.cli.arguments import SubParsers


def add_parser(subparsers: SubParsers) -> None:
    """Declare `policy check` under the `policy` command's actions."""
    pc = subparsers.add_parser("check", help="validate test case files (or directories of them)",
                               epilog="example:\n  astaa-deft policy check policies/examples/demo_*.xml --spec "
                                      "specs/demo_av.yaml")
    pc.add_argument("files", type=Path, nargs="+", help="test case XML files or directories of them")
    pc.add_argument("--spec", type=Path, help="also check channels, fields and values against this spec "
                                              "(default: the XSD only)")
    pc.add_argument("--dictionary", type=Path, action="append", default=[],
                    help="a dictionary whose value names the test cases use (repeatable; default: the bundled one)")
    pc.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The parsed `policy check` arguments to :func:`check_policies`."""
    return check_policies(args.files, args.spec, args.dictionary)


def check_policies(files: Sequence[Path], spec_path: Path | None = None, dictionaries: Sequence[Path] = ()) -> int:
    """Load each test case of ``files`` (a directory: its *.xml) against the spec and dictionaries, print a
    line per file: 0. Raises InputError listing every problem found, after all files were tried."""
    from astaa_deft.engine.intercept.dictionary import load_dictionary
    from astaa_deft.engine.intercept.testcase import load_testcase
    from astaa_deft.engine.spec.loader import load_spec

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
