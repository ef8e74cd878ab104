"""Runtime monitors: the spec's invariants, evaluated online (proxy) and offline (`check`).

    build_invariants(src, node, types, channels, modules)  # the spec loader's `invariants:` section
    MonitorSet(spec, start_ns)                              # evaluate them over one run
    run_verdict(violations, exits, modules) -> RunVerdict  # the run on the CRASH scale
    check_log(log, spec) -> CheckResult                     # the same MonitorSet over a recorded log

See docs/monitors.md for the invariant kinds, the sampling rule and the
CRASH mapping. This package must not import the spec loader at import time:
the loader imports ``monitor.invariants``.
"""

from astaa_deft.engine.monitor.base import Invariant
from astaa_deft.engine.monitor.invariants import build_invariants, with_typed_invariants
from astaa_deft.engine.monitor.monitorset import MonitorSet
from astaa_deft.engine.monitor.offline import CheckResult, check_log
from astaa_deft.engine.monitor.verdict import RunVerdict, format_verdict, run_verdict
from astaa_deft.engine.monitor.violation import Violation, format_violation

__all__ = [
    "CheckResult", "Invariant", "MonitorSet", "RunVerdict", "Violation", "build_invariants", "check_log",
    "format_verdict", "format_violation", "run_verdict", "with_typed_invariants",
]
