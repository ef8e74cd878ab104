"""`astaa-deft spec check FILE [--param KEY=VALUE]`: validate a SUT spec, print what it declares.

Exit 0 when the spec loads (and its planner replay factory imports); bad
input raises InputError (exit 2, printed by the CLI).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.cli.commands.console import parse_params

if TYPE_CHECKING:
    from astaa_deft.cli.arguments import SubParsers
    from astaa_deft.model.sut import Spec


def add_parser(subparsers: SubParsers) -> None:
    """Declare `spec check` under the `spec` command's actions."""
    check = subparsers.add_parser("check", help="validate a SUT spec", epilog=(
        "example:\n  astaa-deft spec check specs/demo_av.yaml --param scenario=cut_in"))
    check.add_argument("file", type=Path, help="the SUT spec (YAML)")
    check.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                       help="also check a param value (against the param's declared choices; repeatable; "
                            "default: none)")
    check.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The parsed `spec check` arguments to :func:`check_spec`."""
    return check_spec(args.file, args.param)


def check_spec(path: Path, params: Sequence[str] = ()) -> int:
    """Load the spec at ``path``, check ``params`` (KEY=VALUE texts) against it and print a summary: 0.

    Raises InputError for a spec that does not load, a param that is not declared or not one of its
    choices, or a planner replay factory that does not import.
    """
    from astaa_deft.engine.spec.loader import load_spec
    from astaa_deft.engine.spec.params import check_param_values

    spec = load_spec(path)
    _check_factory(spec, path)
    given = parse_params(params)
    check_param_values(spec, {name: [value] for name, value in given.items()}, "--param")
    choices = ", ".join(f"{name} one of {'/'.join(values)}" for name, values in spec.param_choices.items())
    print(f"{path}: ok — spec '{spec.name}': {len(spec.modules)} modules, {len(spec.channels)} channels, "
          f"{len(spec.types)} types" + (f"; params: {choices}" if choices else ""))
    return 0


def _check_factory(spec: Spec, path: Path) -> None:
    """Import the planner replay factory the way replay loads it, so a wrong name fails here, not in extract.

    As replay does: from sys.path, or else from the spec's own directory (a planner beside its spec).
    """
    factory = spec.planner.factory if spec.planner is not None else None
    if not factory:
        return
    from astaa_deft.analysis.deft.replay import importable_from

    module_name, _, attr = factory.rpartition(":")
    line = _line_of(path, factory)
    if module_name.endswith(".py"):  # a file relative to the spec: loaded as replay loads it
        from astaa_deft.analysis.deft.replay import load_factory

        try:
            made = load_factory(factory, path.resolve().parent)
        except InputError as exc:
            raise InputError(Problem(str(path), line, None, exc.problems[0].message, exc.problems[0].fix)) from None
        if not callable(made):
            raise InputError(Problem(str(path), line, None, f"planner replay factory '{factory}' is not callable",
                                     "name a class or function in that file"))
        return
    try:
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            spec_dir = path.resolve().parent
            top = module_name.split(".")[0]
            if exc.name != top or not importable_from(spec_dir, top):
                raise
            if str(spec_dir) not in sys.path:
                sys.path.append(str(spec_dir))  # after installed packages, as replay does
            module = importlib.import_module(module_name)
    except Exception as exc:  # the user's module failing to import is their input problem
        raise InputError(Problem(str(path), line, None, f"planner replay factory '{factory}' cannot be imported: "
                                 f"{type(exc).__name__}: {exc}",
                                 "fix the module name, put it next to the spec, or install it")) from None
    if not callable(getattr(module, attr, None)):
        raise InputError(Problem(str(path), line, None,
                                 f"planner replay factory '{factory}': module '{module_name}' has no callable '{attr}'",
                                 "name a class or function in that module"))


def _line_of(path: Path, text: str) -> int | None:
    try:
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
            if text in line:
                return n
    except (OSError, UnicodeDecodeError):
        pass
    return None
