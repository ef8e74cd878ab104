"""What a run's callbacks see of it: :class:`RunView`, a read-only handle on a run in progress."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import zenoh

from astaa_deft.engine.monitor.monitorset import MonitorSet
from astaa_deft.model.records import ProcessExit, Violation

if TYPE_CHECKING:
    from astaa_deft.engine.session.bus_run import BusRun


class RunView:
    """A run in progress as ``on_start`` and ``stop_when`` see it (``run_session``).

    Read-only but for ``subscribe``; every reader may be called from any
    thread and returns a snapshot (a copy or an immutable value).
    """

    __slots__ = ("_run",)

    def __init__(self, run: BusRun):
        self._run = run

    @property
    def run_dir(self) -> Path:
        """The run directory: module logs and configs."""
        return self._run.run_dir

    @property
    def started_ns(self) -> int:
        """When the tool's session opened (``time.time_ns``)."""
        return self._run.started_ns

    @property
    def endpoints(self) -> tuple[str, ...]:
        """The Zenoh endpoints of the run's bus (what the modules and the recorder connect to)."""
        return tuple(self._run.bus_endpoints)

    @property
    def recorder_pid(self) -> int | None:
        """The recorder's process id while it runs (None without a recorder)."""
        return self._run.recorder.pid if self._run.recorder is not None else None

    @property
    def module_pids(self) -> dict[str, int]:
        """The launched modules' process ids, by module name."""
        modules = self._run.modules
        return modules.launcher.pids() if modules is not None and modules.launcher is not None else {}

    @property
    def violations(self) -> tuple[Violation, ...]:
        """The findings so far."""
        return tuple(self._run.violations)

    @property
    def exits(self) -> tuple[ProcessExit, ...]:
        """The modules' exits so far."""
        return tuple(self._run.exits)

    @property
    def mutations(self) -> int:
        """Messages the interception changed so far."""
        return self._run.mutations

    @property
    def monitor_set(self) -> MonitorSet | None:
        """The online monitors' state (its ``stats`` stay readable after the run); None before the judge starts."""
        return self._run.judge.monitor_set if self._run.judge is not None else None

    def counts(self) -> dict[str, int]:
        """Messages per channel forwarded (star) or observed (passive) so far."""
        return self._run.counts()

    def crashed(self) -> tuple[ProcessExit, ...]:
        """The modules' abnormal exits so far."""
        return tuple(self._run.crashed())

    def subscribe(self, channel: str, callback: Callable[[zenoh.Sample], None]) -> None:
        """Watch a declared channel (as its producer published it) from the tool's session, on Zenoh's thread.

        Raises KeyError when the channel is not observable in this mode.
        Call it from the session's thread (``on_start``).
        """
        self._run.subscribe(channel, callback)
