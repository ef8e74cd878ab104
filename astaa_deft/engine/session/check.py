"""The offline check as one library call: a recorded run judged by its spec's invariants.

``check_recorded_run(log_path, spec_path)`` reads the log, takes the spec
given (or the one stored in the log), and evaluates every invariant over the
recorded messages (:func:`astaa_deft.engine.monitor.offline.check_log`).
``astaa-deft check`` prints the result and picks the exit code; the minimiser
and campaigns call ``check_log`` on logs they hold already. It sits in the
session layer, above the spec loader: judging a recorded run is the offline
half of what ``run_session`` does live.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.log.reader import LogContents, read_log
from astaa_deft.engine.monitor.invariants import with_typed_invariants
from astaa_deft.engine.monitor.offline import CheckResult, check_log
from astaa_deft.model.sut import Spec
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.engine.spec.stored import spec_from_log


@dataclass(frozen=True)
class RecordedCheck:
    result: CheckResult
    spec: Spec  # the spec judged against, invariants typed
    spec_from_log: bool  # True: the spec stored in the log (no spec path given)
    log: LogContents  # what was read, with its damage (``log.intact`` False: no Pass may be given)

    @property
    def passed(self) -> bool:
        return self.result.passed


def check_recorded_run(log_path: Path, spec_path: Path | None = None) -> RecordedCheck:
    """Judge the run in ``log_path`` (InputError: a log with nothing readable, a bad spec, or no spec at all).

    A damaged or cut log is judged on what could be read; the caller decides
    from ``log.intact`` whether a verdict may be given (never a Pass).
    """
    log = read_log(log_path)
    if not log.messages:
        raise InputError(Problem(str(log_path), None, None, f"nothing in the log could be read "
                                 f"({log.describe_reading()}), so there is nothing to judge",
                                 "check the file is the log of a run"))
    spec: Spec | None
    if spec_path is not None:
        spec = load_spec(spec_path)
    else:
        spec = spec_from_log(log, f"{log_path}:spec.yaml")
        if spec is None:
            raise InputError(Problem(str(log_path), None, None, "the log holds no spec to check it against",
                                     "give the SUT spec with --spec sut.yaml"))
    spec = with_typed_invariants(spec)
    return RecordedCheck(check_log(log, spec), spec, spec_path is None, log)
