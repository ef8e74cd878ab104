"""Minimise a failing run to the few mutations, frames or fields that cause it.

The engine (:mod:`.ddmin`) knows nothing of runs: it takes items and a tester.
The whole workflow is one call, :func:`.workflow.minimise_log` (not imported
here: it brings the testers, the replay and the live session with it).
"""

from astaa_deft.analysis.minimise.ddmin import (
    Config,
    DDOptions,
    DDResult,
    FailsWithoutItems,
    GroupResult,
    MinimiseError,
    NotReproducible,
    Outcome,
    OutcomeCache,
    Tester,
    TestResult,
    ddmin,
    minimise_groups,
)

__all__ = [
    "Config",
    "DDOptions",
    "DDResult",
    "FailsWithoutItems",
    "GroupResult",
    "MinimiseError",
    "NotReproducible",
    "Outcome",
    "OutcomeCache",
    "TestResult",
    "Tester",
    "ddmin",
    "minimise_groups",
]
