"""The spec's planner section, for the code that cannot work without one.

``Spec.planner`` is None when the spec has no ``planner:`` section; every
workflow of DeFT (extraction, module-test suites, the planner replay of a
minimisation) checks that first and refuses with a clear message. This is
the typed way for the code below those checks to get the section.
"""

from __future__ import annotations

from ..errors import InputError, Problem
from ..spec.model import Spec
from ..spec.planner import PlannerSpec


def planner_of(spec: Spec) -> PlannerSpec:
    """The spec's planner section (InputError naming the spec when it has none)."""
    if spec.planner is None:
        raise InputError(Problem(str(spec.path) if spec.path else spec.name, None, None,
                                 "the spec has no 'planner' section",
                                 "describe the planning module under 'planner:' (see docs/deft.md)"))
    return spec.planner
