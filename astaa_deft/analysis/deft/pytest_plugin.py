"""pytest plugin: `pytest DIR` runs an exported DeFT suite (DIR/deft.json).

Registered through the `pytest11` entry point, so any environment with
astaa-deft installed runs extracted module tests with plain pytest. One test
per frame, in order; a failure shows where the replayed trajectory left the
recorded one.

With ``ASTAA_DEFT_SUITE_RESULTS`` set to a file, the run also writes there
every frame's result (the frames stepped for their state too) when it ends:
how extraction checks a suite it wrote — pytest's own run of it, in a
process of its own, so the tool never says a suite passes that pytest fails.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from astaa_deft.model.errors import AstaaDeftError
from astaa_deft.analysis.deft.export import MANIFEST, is_checked

if TYPE_CHECKING:
    from _pytest._code.code import TerminalRepr, TracebackStyle

    from astaa_deft.analysis.deft.oracle_entry import OracleEntry
    from astaa_deft.analysis.deft.suite import FrameResult, Suite


RESULTS_ENV = "ASTAA_DEFT_SUITE_RESULTS"  # a file: every frame's result of this run, written at its end
_collected: list[Suite] = []  # the suites this run collected (for RESULTS_ENV)


def pytest_collect_file(file_path: Path, parent: pytest.Collector) -> DeftSuiteFile | None:
    if file_path.name == MANIFEST:
        return DeftSuiteFile.from_parent(parent, path=file_path)
    return None


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    """With RESULTS_ENV set: each collected suite's frame results as this run replayed them (replayed now if no
    test of it ran: every frame is stepped for its state only)."""
    target = os.environ.get(RESULTS_ENV)
    if not target or not _collected:
        return
    suites: dict[str, dict[str, object]] = {}
    for suite in _collected:
        try:
            results = suite.results()
        except Exception as exc:  # noqa: BLE001 - a suite that cannot run at all: every frame fails
            suites[str(suite.directory.resolve())] = {"error": f"{type(exc).__name__}: {exc}"}
            continue
        suites[str(suite.directory.resolve())] = {"frames": [
            {"index": r.index, "passes": r.error is None and r.comparison.within(suite.threshold),
             "distance": r.comparison.distance, "max_error": r.comparison.max_error, "points": r.comparison.points,
             "how": r.comparison.how, "error": r.error, "stopped": r.stopped} for r in results]}
    Path(target).write_text(json.dumps(suites, default=repr), encoding="utf-8")


class DeftSuiteFile(pytest.File):
    def collect(self) -> Iterator[pytest.Item]:
        from astaa_deft.analysis.deft.suite import Suite

        suite = Suite(self.path.parent)
        if os.environ.get(RESULTS_ENV):  # kept for the run's end only when asked (a suite holds its replay)
            _collected.append(suite)
        oracles = list(enumerate(suite.oracles))
        # Oracle tests with a snapshot of the state before their frame run first: one step each, so a
        # suite that reproduces a failure fails at once (pytest -x) instead of after the whole replay.
        for n, oracle in oracles:
            if oracle.snapshot:
                yield OracleTest.from_parent(self, name=f"oracle_{oracle.kind}_{n:03d}", suite=suite,
                                             oracle=oracle)
        for position, entry in enumerate(suite.frames):
            if not is_checked(entry):
                continue  # stepped for the state it builds (not reproduced within θ when extracted)
            yield FrameTest.from_parent(self, name=f"frame_{entry['index']:05d}", suite=suite, position=position)
        for n, oracle in oracles:
            if not oracle.snapshot:
                yield OracleTest.from_parent(self, name=f"oracle_{oracle.kind}_{n:03d}", suite=suite,
                                             oracle=oracle)


class FrameMismatch(AstaaDeftError):
    pass


class FrameTest(pytest.Item):
    # ``kwargs``: pytest's own node arguments (name, parent, ...), passed on untouched, as its cooperative
    # constructors must; Any because pytest.Item.__init__ types each differently and leaves some untyped.
    def __init__(self, *, suite: Suite, position: int, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.suite = suite  # shared by the file's tests: the frames are replayed once, in order
        self.position = position

    def runtest(self) -> None:
        suite = self.suite
        result = suite.results()[self.position]
        if result.error or not result.comparison.within(suite.threshold):
            raise FrameMismatch(result)

    def repr_failure(self, excinfo: pytest.ExceptionInfo[BaseException],
                     style: TracebackStyle | None = None) -> str | TerminalRepr:
        if not isinstance(excinfo.value, FrameMismatch):
            return super().repr_failure(excinfo)
        r = excinfo.value.args[0]
        if self.suite.entry.trajectory is None:
            return self._fields_failure(r)
        lines = [f"frame {r.index}: the planner's output changed"]
        if r.error:
            lines.append(f"  the planner raised {r.error}")
        c = r.comparison
        lines.append(f"  distance {c.distance:.6g} m (threshold {self.suite.threshold:g} m), "
                     f"largest point error {c.max_error:.6g} m over {c.points} points ({c.how})")
        lines.append(f"  {'t':>10} {'recorded x,y':>24} {'replayed x,y':>24}")
        for i in range(min(6, max(len(r.expected), len(r.replayed)))):
            e = r.expected[i] if i < len(r.expected) else None
            p = r.replayed[i] if i < len(r.replayed) else None
            point = e if e is not None else p
            t = point[2] if point is not None else 0.0  # one of the two exists below max(len, len)
            fmt = lambda q: f"{q[0]:11.4f},{q[1]:11.4f}" if q else f"{'—':>23}"  # noqa: E731
            lines.append(f"  {t:10.3f} {fmt(e):>24} {fmt(p):>24}")
        return "\n".join(lines)

    def _fields_failure(self, r: FrameResult) -> str:
        """Any other module's output: where the replayed message left the recorded one, field by field."""
        from astaa_deft.analysis.deft.validator import differing_fields

        entry = self.suite.entry
        lines = [f"frame {r.index}: module '{entry.module}''s output on '{entry.output}' changed"]
        if r.error:
            lines.append(f"  the module raised {r.error}" if r.stopped == "crash" else f"  {r.error}")
        else:
            c = r.comparison
            lines.append(f"  distance {c.distance:.6g} (threshold {self.suite.threshold:g}), largest field error "
                         f"{c.max_error:.6g} over {c.points} fields ({c.how})")
        if r.error:
            pass  # no output to compare: the error says it all
        elif r.expected_message is None and r.message is not None:
            lines.append("  recorded: no output for this frame; replayed: an output")
        elif r.message is None and r.expected_message is not None and not r.error:
            lines.append("  recorded: an output; replayed: none")
        else:
            lines.append(f"  {'field':<28} {'recorded':>22} {'replayed':>22}")
            for path, recorded, replayed in differing_fields(r.message, r.expected_message, entry.ignore):
                lines.append(f"  {path:<28} {recorded!s:>22} {replayed!s:>22}")
        return "\n".join(lines)

    def reportinfo(self) -> tuple[Path, int | None, str]:
        return self.path, None, f"DeFT {self.name}"


class OracleFailure(AstaaDeftError):
    pass


class OracleTest(pytest.Item):
    def __init__(self, *, suite: Suite, oracle: OracleEntry, **kwargs: Any) -> None:  # kwargs: as FrameTest's
        super().__init__(**kwargs)
        self.suite = suite
        self.oracle = oracle

    def runtest(self) -> None:
        from astaa_deft.analysis.deft.oracle import check_oracle

        problem = check_oracle(self.suite, self.oracle)
        if problem:
            raise OracleFailure(problem)

    def repr_failure(self, excinfo: pytest.ExceptionInfo[BaseException],
                     style: TracebackStyle | None = None) -> str | TerminalRepr:
        if isinstance(excinfo.value, OracleFailure):
            return f"oracle {self.oracle.kind}: {excinfo.value}"
        return super().repr_failure(excinfo)

    def reportinfo(self) -> tuple[Path, int | None, str]:
        return self.path, None, f"DeFT oracle {self.name}"
