"""The tool's own helper processes in a run: the bus router (passive mode), the recorder, and the drain before it stops.

A helper says ``ready`` on its stdout once it can do its job; a helper that
stops before the run does means the run is not fully observed or recorded
(:meth:`HelperProcess.lost`).
"""

from __future__ import annotations

import json
import signal
import subprocess
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from astaa_deft.engine.bus import process_launch
from astaa_deft.engine.bus.processes import ChildProcess, python_module, stop_process, tail
from astaa_deft.engine.session.parts import EventLog, RunPart
from astaa_deft.io.inputfile import SPEC, read_input
from astaa_deft.io.output_place import open_new
from astaa_deft.io.log import records as rec
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.sut import Spec

HELPER_READY_TIMEOUT = 20.0
DRAIN_SECONDS = 0.3  # after the modules stop, let in-flight messages reach the tool's subscribers
SUBSCRIBED_LIMIT = 2.0  # for the router to see the recorder's subscribers after its 'ready'
CATCH_UP_LIMIT = 15.0  # at most this long for a recorder that fell behind to read its backlog
RECORDER_CAUGHT_UP = "caught up"  # the recorder's line once the run_stopped event (and all before it) arrived


@dataclass(frozen=True, kw_only=True)
class HelperStart:
    """How to start one helper: its name, argv, text for its stdin, and the file its failure is about."""

    name: str  # "recorder" | "bus router"
    args: list[str]
    stdin_text: str | None = None
    error_file: Path | None = None  # named in the problem if it does not start (else the spec)
    warm: ChildProcess | None = None  # started ahead and waiting for stdin_text (then args are unused)


@dataclass(kw_only=True)
class HelperProcess:
    """One started helper: its process, its stdout lines as they come (read by a thread of its own) and its log."""

    name: str
    process: ChildProcess
    log_path: Path
    lines: list[str] = field(default_factory=list)
    _reader: threading.Thread | None = None

    @classmethod
    def launch(cls, how: HelperStart, run_dir: Path) -> HelperProcess:
        """Start it (or take the warm one) and write its stdin; :meth:`wait_ready` next."""
        log_path = run_dir / f"{how.name.split()[-1]}.log"
        if how.warm is not None:
            proc = how.warm
        else:
            with open_new(log_path, "--run-dir") as err:
                proc = process_launch.start(how.args, stdout=subprocess.PIPE, stderr=err, text=True,
                                            stdin=subprocess.DEVNULL if how.stdin_text is None else subprocess.PIPE)
        if how.stdin_text is not None:
            assert proc.stdin is not None
            try:
                proc.stdin.write(how.stdin_text)
                proc.stdin.close()
            except BrokenPipeError:  # it died at once: the ready check says why
                pass
        return cls(name=how.name, process=proc, log_path=log_path)

    def wait_ready(self, how: HelperStart, spec: Spec) -> None:
        """Wait for its 'ready' line; raises InputError (with its log's tail) if it does not come."""
        if not self._wait_ready():
            raise InputError(Problem(str(how.error_file or spec.path), None, None,
                                     f"the {how.name} did not start:\n{tail(self.log_path)}",
                                     "see the message above" + (" (is the log path writable?)"
                                                                if how.error_file else "")))

    def _wait_ready(self) -> bool:
        ready = threading.Event()
        lines, proc = self.lines, self.process

        def read() -> None:
            assert proc.stdout is not None
            for line in proc.stdout:
                lines.append(line.strip())
                if line.strip() == "ready":
                    ready.set()
            ready.set()

        self._reader = threading.Thread(target=read, daemon=True)
        self._reader.start()
        return ready.wait(HELPER_READY_TIMEOUT) and "ready" in lines

    def lost(self) -> str:
        """Why it stopped ("" while it runs)."""
        code = self.process.poll()
        if code is None:
            return ""
        how = f"killed by {signal.Signals(-code).name}" if code < 0 and -code in signal.valid_signals() \
            else f"exit code {code}"
        why = tail(self.log_path, lines=3).strip()
        return f"the {self.name} stopped ({how})" + (f": {why}" if why else "")

    def stop(self, grace: float) -> None:
        """Stop its process group (SIGTERM, SIGKILL after ``grace`` s) and let its reader finish."""
        stop_process(self.process, grace=grace)
        if self._reader is not None:
            self._reader.join(timeout=5.0)


class Helpers:
    """The helpers of one run, for noticing the loss of any (read from the run loop's thread)."""

    def __init__(self) -> None:
        self.started: list[HelperProcess] = []
        self.lost = ""  # why a helper of ours stopped mid-run: the run is not fully observed or recorded

    def launch(self, how: HelperStart, run_dir: Path, spec: Spec,
               keep: Callable[[HelperProcess], None] = lambda helper: None) -> HelperProcess:
        """Start one helper, counted among this run's (and handed to ``keep``) before it is ready, so a helper
        that never says 'ready' is stopped with the rest; raises InputError then."""
        helper = HelperProcess.launch(how, run_dir)
        self.started.append(helper)
        keep(helper)
        helper.wait_ready(how, spec)
        return helper

    def check(self) -> str:
        """Why a helper stopped before the run did ("" while all run); the first reason is kept."""
        if not self.lost:
            self.lost = next((why for why in (h.lost() for h in self.started) if why), "")
        return self.lost


class BusRouter(RunPart):
    """The bus's router in passive mode (the tool is then one client among the modules); stopped last."""

    def __init__(self, listen: list[str], run_dir: Callable[[], Path], spec: Spec, helpers: Helpers):
        self._how = HelperStart(name="bus router", args=[*python_module("astaa_deft.engine.bus.router"),
                                               *[a for ep in listen for a in ("--listen", ep)]])
        self._run_dir, self._spec, self._helpers = run_dir, spec, helpers
        self.helper: HelperProcess | None = None

    def start(self) -> None:
        self._helpers.launch(self._how, self._run_dir(), self._spec, keep=self._keep)

    def _keep(self, helper: HelperProcess) -> None:
        self.helper = helper

    def close(self) -> None:
        if self.helper is not None:  # everyone else has let go of it
            self.helper.stop(grace=5.0)


@dataclass(frozen=True, kw_only=True)
class RecorderRequest:
    """What the recorder is told: where to write, what to connect to, what to attach and expect."""

    path: Path
    mode: str
    meta: dict[str, str]
    endpoints: list[str]
    intercepted: list[str]
    attachments: dict[str, Path]
    warm: ChildProcess | None  # started ahead (``bus_run.warm_recorder``): used if still alive


class Recorder(RunPart):
    """The recorder process, given the spec's text on stdin; subscribed before the run's first event.

    ``recorded`` (messages per channel it wrote) and ``finished`` (it
    reported its counts and exited cleanly) are set at close.
    """

    def __init__(self, request: RecorderRequest, spec: Spec, run_dir: Callable[[], Path], *,
                 events: EventLog, helpers: Helpers):
        self._request, self._spec, self._run_dir = request, spec, run_dir
        self._events, self._helpers = events, helpers
        self.helper: HelperProcess | None = None
        self.recorded: dict[str, int] = {}
        self.finished = False

    @property
    def pid(self) -> int | None:
        """The recorder's process id while it runs (None before its start and after its stop)."""
        return self.helper.process.pid if self.helper is not None else None

    def start(self) -> None:
        how = self._how()
        self.helper = self._helpers.launch(how, self._run_dir(), self._spec, keep=self._keep)
        self._wait_subscribed()

    def _keep(self, helper: HelperProcess) -> None:
        self.helper = helper

    def _how(self) -> HelperStart:
        req, spec = self._request, self._spec
        args = ["--out", str(req.path),
                "--spec-name", spec.path.name if spec.path is not None else f"{spec.name}.yaml",
                "--mode", req.mode, "--meta", json.dumps(req.meta)]
        for ep in req.endpoints:
            args += ["--connect", ep]
        for name in req.intercepted:
            args += ["--intercepted", name]
        for name, file in req.attachments.items():
            args += ["--attach", f"{name}={file}"]
        # The spec travels as its text on stdin: the recorder reads the session's spec, not a file.
        spec_text = spec.source_text or (read_input(spec.path, SPEC).decode("utf-8") if spec.path is not None else "")
        if req.warm is not None and req.warm.poll() is None:  # started ahead (imports done): hand it its arguments
            args = ["--log-file", str(self._run_dir() / "recorder.log"), *args]
            return HelperStart(name="recorder", args=args, stdin_text=json.dumps(args) + "\n" + spec_text,
                               error_file=req.path, warm=req.warm)
        return HelperStart(name="recorder", args=[*python_module("astaa_deft.engine.session.recorder"), *args],
                           stdin_text=spec_text, error_file=req.path)

    def _wait_subscribed(self) -> None:
        """The recorder says 'ready' once it declared its subscribers; the router may learn of them a moment
        later, and an event published in between (run_started) would miss the log. Wait until our events
        publisher sees a subscriber (bounded: a Zenoh that does not report matching must not stall runs)."""
        publisher = self._events.publisher
        assert publisher is not None and self.helper is not None
        deadline = time.monotonic() + SUBSCRIBED_LIMIT
        while time.monotonic() < deadline and self.helper.process.poll() is None:
            try:
                # zenoh's stub types Publisher.matching_status as bool; at run time it is a MatchingStatus.
                if publisher.matching_status.matching:  # type: ignore[attr-defined]
                    return
            except zenoh.ZError:
                return
            time.sleep(0.005)

    def wait_caught_up(self) -> None:
        """A recorder behind (a burst, a slow disk) still holds messages in its socket: stopping it now would
        lose them. It says when the run_stopped event has arrived, i.e. everything sent before it. Not
        waited for when a helper is lost: nothing reaches the recorder any more."""
        if self.helper is None or self._helpers.check():
            return
        deadline = time.monotonic() + CATCH_UP_LIMIT
        while (RECORDER_CAUGHT_UP not in self.helper.lines and self.helper.process.poll() is None
               and time.monotonic() < deadline):
            time.sleep(0.02)

    def close(self) -> None:
        if self.helper is None:
            return
        self.helper.stop(grace=30.0)
        for line in self.helper.lines:
            if line.startswith("{"):
                self.recorded = json.loads(line).get("recorded", {})
                self.finished = self.helper.process.returncode == 0
        self.helper = None


class Drain(RunPart):
    """After the modules stop: say so in the log, let in-flight messages arrive, wait for the recorder to catch up."""

    def __init__(self, events: EventLog, recorder: Recorder | None, needed: Callable[[], bool]):
        self._events, self._recorder, self._needed = events, recorder, needed

    def close(self) -> None:
        if not self._needed():
            return
        self._events.emit(rec.RunStopped(time.time_ns()))
        time.sleep(DRAIN_SECONDS)
        if self._recorder is not None:
            self._recorder.wait_caught_up()
