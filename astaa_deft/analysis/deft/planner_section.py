"""The spec's planner section and its other replayable modules, for the code that cannot work without one.

``Spec.planner`` is None when the spec has no ``planner:`` section; every
workflow of DeFT (extraction, module-test suites, the planner replay of a
minimisation) checks that first and refuses with a clear message. This is
the typed way for the code below those checks to get the section.
"""

from __future__ import annotations

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.replay_module import ReplayModule


def planner_of(spec: Spec) -> ReplayModule:
    """The spec's planner section (InputError naming the spec when it has none)."""
    if spec.planner is None:
        raise InputError(Problem(str(spec.path) if spec.path else spec.name, None, None,
                                 "the spec has no 'planner' section",
                                 "describe the planning module under 'planner:' (see docs/deft.md)"))
    return spec.planner


def replay_modules(spec: Spec) -> tuple[ReplayModule, ...]:
    """Every module of the spec that can run alone: the planner (if any) first, then ``replay.modules``."""
    planner = (spec.planner,) if spec.planner is not None else ()
    return planner + tuple(spec.replay)


def replay_module_of(spec: Spec, module: str | None = None, output: str | None = None) -> ReplayModule:
    """The replay entry of ``module`` (None: the planner), or an InputError naming the spec and the fix.

    ``output`` picks among a module's entries (one per output); default: its first.
    """
    if module is None:
        return planner_of(spec)
    entries = replay_modules(spec)
    found = next((e for e in entries if e.module == module and output in (None, e.output)), None)
    if found is None:
        names = [e.module for e in entries]
        raise InputError(Problem(str(spec.path) if spec.path else spec.name, None, None,
                                 f"module '{module}' cannot run alone: the spec names no replay for it",
                                 (f"replayable: {', '.join(names)}; or " if names else "")
                                 + "add it under 'replay: modules:' (see docs/spec.md)"))
    return found
