"""The parts a run is built from, and the two every other part leans on: the run directory and the tool's session.

A run (:class:`~astaa_deft.engine.session.bus_run.BusRun`) starts its parts
in order and registers each one's ``close`` on an ``ExitStack`` *before*
starting it, so a part that fails half-way is closed with the rest, and the
stop order is the start order reversed. Between the two, every started part
hears ``stopping`` (in start order) once the run begins to stop: the moment to
judge, release held messages or report, while everything is still up.
"""

from __future__ import annotations

import tempfile
import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from types import TracebackType

import zenoh

from astaa_deft.engine.bus import topology
from astaa_deft.engine.bus import zenoh_config as zc
from astaa_deft.io.log import records as rec
from astaa_deft.io.output_place import Place, check_temp_dir, ready_dir
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.sut import Spec


class RunPart:
    """One context-managed part of a run; every hook does nothing unless a part overrides it.

    * ``start()``: bring the part up (raises ``InputError`` when it cannot);
      ``close`` is already registered, so it must cope with a partial start.
    * ``stopping()``: the run begins to stop; every part still up.
    * ``close()``: let go of everything the part holds; called once, from
      the thread that runs the session, whatever ended the run.
    """

    def start(self) -> None:
        """Bring the part up."""

    def stopping(self) -> None:
        """The run begins to stop (before any part closes)."""

    def close(self) -> None:
        """Let go of everything the part holds."""

    def __enter__(self) -> RunPart:
        self.start()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


class EventLog:
    """The run's events: kept, published on the tool's events key (the recorder logs them) and handed on.

    ``emit`` may be called from any thread; ``on_event`` is called from the
    emitting thread.
    """

    def __init__(self, on_event: Callable[[rec.Record], None] | None):
        self.on_event: Callable[[rec.Record], None] = on_event or (lambda event: None)
        self.listening = on_event is not None  # mutations become typed records only for a listener
        self.records: list[rec.Record] = []
        self.publisher: zenoh.Publisher | None = None  # set while the tool's session is open
        self._lock = threading.Lock()

    def emit(self, record: rec.Record) -> rec.Record:
        """Log one event and hand it to ``on_event``; returns it."""
        with self._lock:
            self.records.append(record)
        publisher = self.publisher
        if publisher is not None:
            publisher.put(rec.to_json_text(record))
        self.on_event(record)
        return record


class RunDirectory(RunPart):
    """Where module logs and configs go: ``given`` (made ready, absolute) or a fresh temporary folder.

    A temporary folder is removed at close; a given one is kept.
    """

    def __init__(self, spec_name: str, given: Path | None):
        self._spec_name = spec_name
        self._given = given
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        self.path = Path()

    def start(self) -> None:
        if self._given is None:
            check_temp_dir()
            self._tmp = tempfile.TemporaryDirectory(prefix=f"astaa-deft-{self._spec_name}-")
            self.path = Path(self._tmp.name)
        else:
            # Absolute: the paths handed to modules (ZENOH_CONFIG…) must hold from a module's own cwd too.
            self.path = ready_dir(Place(self._given.resolve(), "--run-dir"))

    def close(self) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None


class ToolSession(RunPart):
    """The tool's own Zenoh session and its events publisher (attached to ``events`` while open)."""

    def __init__(self, spec: Spec, config: Mapping[str, object], listen: list[str], events: EventLog):
        self._spec = spec
        self._config = config
        self._listen = listen
        self._events = events
        self._session: zenoh.Session | None = None

    @property
    def session(self) -> zenoh.Session:
        """The open session (only between ``start`` and ``close``)."""
        assert self._session is not None, "the tool's session is not open"
        return self._session

    def start(self) -> None:
        try:
            self._session = zc.open_session(self._config, self._spec.zenoh.config_file)
        except zenoh.ZError as exc:
            where = str(self._spec.path or "<spec>")
            raise InputError(Problem(
                where, None, None,
                f"cannot open the tool's Zenoh session on {', '.join(self._listen)}: {exc}",
                "the port may be in use: set 'zenoh.endpoints' to another port, or port 0 for a free one",
            )) from None
        self._events.publisher = self._session.declare_publisher(topology.EVENTS_KEY)

    def close(self) -> None:
        if self._session is not None:
            self._events.publisher = None
            self._session.close()
            self._session = None
