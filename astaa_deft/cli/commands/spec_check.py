"""`astaa-deft spec check FILE`."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Sequence
from pathlib import Path

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.analysis.deft.replay import importable_from
from astaa_deft.engine.spec.params import check_param_values
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.cli.commands.console import parse_params


def run(path: Path, params: Sequence[str] = ()) -> int:
    spec = load_spec(path)
    _check_factory(spec, path)
    given = parse_params(params)
    check_param_values(spec, {name: [value] for name, value in given.items()}, "--param")
    choices = ", ".join(f"{name} one of {'/'.join(values)}" for name, values in spec.param_choices.items())
    print(f"{path}: ok — spec '{spec.name}': {len(spec.modules)} modules, {len(spec.channels)} channels, "
          f"{len(spec.types)} types" + (f"; params: {choices}" if choices else ""))
    return 0


def _check_factory(spec, path: Path) -> None:
    """Import the planner replay factory the way replay loads it, so a wrong name fails here, not in extract.

    As replay does: from sys.path, or else from the spec's own directory (a planner beside its spec).
    """
    factory = spec.planner.factory if spec.planner is not None else None
    if not factory:
        return
    module_name, _, attr = factory.partition(":")
    line = _line_of(path, factory)
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
