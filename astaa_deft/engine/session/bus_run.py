"""One run of the SUT on the bus, built from parts (:mod:`~astaa_deft.engine.session.parts`).

Start order: the run directory, the bus router (passive mode), the tool's
session, the transport (star proxy and interception, or the passive
observer), the recorder (subscribed before any module speaks), the judge
(online monitors), then the modules in spec order. Each part's ``close`` is
registered on an ``ExitStack`` before the part starts (``parts.RunPart``),
so the stop order is the start order reversed — the modules first, the
recorder after the last message reached it, the router last — and the log is
finished cleanly whatever ended the run. :func:`run_session` drives a run.
"""

from __future__ import annotations

import contextlib
import json
import subprocess
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import zenoh

from astaa_deft.engine.bus import process_launch
from astaa_deft.engine.bus import topology
from astaa_deft.engine.bus import zenoh_config as zc
from astaa_deft.model.records import ProcessExit, RunMode, Violation
from astaa_deft.engine.bus.processes import ChildProcess, python_module
from astaa_deft.engine.session.helpers import BusRouter, Drain, Helpers, Recorder, RecorderRequest
from astaa_deft.engine.session.judge import Judge
from astaa_deft.engine.session.modules import Modules, ModulesPlace
from astaa_deft.engine.session.options import RunOptions
from astaa_deft.engine.session.parts import EventLog, RunDirectory, RunPart, ToolSession
from astaa_deft.engine.session.transport import Transport
from astaa_deft.io.log import records as rec
from astaa_deft.io.output_place import Place, ready_file
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.sut import Spec

PartT = TypeVar("PartT", bound=RunPart)


@dataclass(frozen=True)
class BusPlan:
    """Where the run's bus is: the tool's Zenoh config, what it listens on, what modules connect to."""

    tool_config: Mapping[str, object]
    listen: list[str]
    endpoints: list[str]
    router: bool  # a bus router of ours (passive mode): the tool is one client among the modules


class BusRun:
    """One run of the SUT: its parts, started in order by ``start`` (or ``with``), stopped in reverse by ``stop``.

    ``on_event`` gets every event as a typed record, from the thread that
    produced it. ``start``, ``end``, ``stop`` and ``subscribe`` are called
    from the thread that runs the session; the accessors from any thread.
    Raises ``InputError`` (from ``start``) when the run cannot start; the
    parts started so far are stopped then.
    """

    def __init__(self, spec: Spec, options: RunOptions,
                 on_event: Callable[[rec.Record], None] | None = None):
        self.spec = spec
        self.options = options
        self.events = EventLog(on_event)
        self.helpers = Helpers()
        self.directory = RunDirectory(spec.name, options.run_dir)
        self.bus_endpoints: list[str] = []
        self.started_ns = 0
        self.end_reason = ""
        self.router: BusRouter | None = None
        self.tool: ToolSession | None = None
        self.transport: Transport | None = None
        self.recorder: Recorder | None = None
        self.judge: Judge | None = None
        self.modules: Modules | None = None
        self._subs: list[zenoh.Subscriber[None]] = []
        self._parts: list[RunPart] = []
        self._stack = contextlib.ExitStack()

    # -- lifecycle ---------------------------------------------------------
    def __enter__(self) -> BusRun:
        try:
            self.start()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def start(self) -> None:
        """Start every part in order (see the module's docstring)."""
        opts, spec = self.options, self.spec
        if opts.interceptor is not None and opts.mode != RunMode.STAR:
            raise InputError("a policy needs the star: interception cannot run with --passive")
        # Both output places are checked before anything starts (OutputError: the place cannot take files).
        if opts.record is not None:
            _check_writable(opts.record)
        self._add(self.directory)
        plan = _bus_plan(spec, opts)
        self.bus_endpoints = plan.endpoints
        if plan.router:
            self.router = self._add(BusRouter(plan.listen, self._run_dir, spec, self.helpers))
        self.tool = self._add(ToolSession(spec, plan.tool_config, plan.listen, self.events))
        self.started_ns = time.time_ns()
        self.transport = self._add(Transport(spec, opts, self.tool, self.events))
        if opts.record is not None:
            self.recorder = self._add(Recorder(self._recorder_request(opts.record, self.transport), spec,
                                               self._run_dir, events=self.events, helpers=self.helpers))
        self._add(Drain(self.events, self.recorder, needed=lambda: self.modules is not None or
                        self.recorder is not None))
        self.judge = self._add(Judge(spec, opts, session=self.tool, transport=self.transport, events=self.events))
        if opts.launch:
            self.modules = self._add(Modules(spec, opts, ModulesPlace(self.directory.path, self.bus_endpoints[0]),
                                             transport=self.transport, judge=self.judge, events=self.events))

    def _add(self, part: PartT) -> PartT:
        """Start ``part``, its close registered first: a part that fails half-way is closed with the rest."""
        self._stack.push(part)
        self._parts.append(part)
        part.start()
        return part

    def stop(self) -> None:
        """Every part hears ``stopping`` (in start order), then closes (in reverse); once."""
        parts, self._parts = self._parts, []
        try:
            for part in parts:
                part.stopping()
        finally:
            self._stack.close()

    def _run_dir(self) -> Path:
        return self.directory.path

    def _recorder_request(self, path: Path, transport: Transport) -> RecorderRequest:
        meta = {"spec": self.spec.name, "command_line": " ".join(self.options.command_line),
                "started_ns": str(self.started_ns),
                "params": json.dumps({**self.spec.params, **self.options.params}, sort_keys=True)}
        return RecorderRequest(path=path, mode=self.options.mode, meta=meta, endpoints=self.bus_endpoints,
                               intercepted=sorted(transport.intercepted), attachments=self.options.attachments,
                               warm=self.options.warm_recorder)

    # -- observation -------------------------------------------------------
    @property
    def run_dir(self) -> Path:
        """The run directory (module logs and configs)."""
        return self.directory.path

    @property
    def lost(self) -> str:
        """Why a helper of ours stopped mid-run ("" if none did): the run is not fully observed or recorded."""
        return self.helpers.lost

    @property
    def exits(self) -> list[ProcessExit]:
        """The modules' exits so far."""
        return self.modules.exits if self.modules is not None else []

    @property
    def violations(self) -> list[Violation]:
        """The findings so far."""
        return self.judge.violations if self.judge is not None else []

    @property
    def mutations(self) -> int:
        """Messages the interception changed so far."""
        return self.transport.mutations if self.transport is not None else 0

    def counts(self) -> dict[str, int]:
        """Messages per channel forwarded (star) or observed (passive) so far."""
        return self.transport.counts() if self.transport is not None else {}

    def subscribe(self, channel: str, callback: Callable[[zenoh.Sample], None]) -> None:
        """Watch a declared channel from the tool (as its producer published it); KeyError if not observable."""
        key = dict((ch.name, k) for k, ch in topology.observed_keys(self.spec, self.options.mode))[channel]
        assert self.tool is not None
        self._subs.append(self.tool.session.declare_subscriber(key, callback))

    def helper_lost(self) -> str:
        """Why the recorder or the bus router stopped before the run did ("" while both run).

        Either loss ends the run: without its recorder the log is incomplete,
        without its router nothing more of the bus is seen; no verdict can then
        be a Pass. The first reason is kept in ``lost``.
        """
        return self.helpers.check()

    def crashed(self) -> list[ProcessExit]:
        """The modules' abnormal exits so far."""
        return self.modules.crashed() if self.modules is not None else []

    def alive(self) -> list[str]:
        """The modules still running."""
        return self.modules.alive() if self.modules is not None else []

    # -- events ------------------------------------------------------------
    def emit(self, record: rec.Record) -> rec.Record:
        """Log one event (the recorder writes what the tool publishes) and hand it to ``on_event``."""
        return self.events.emit(record)

    def end(self, reason: str, at_ns: int | None = None) -> None:
        """Say in the log why the run ends (before the modules are stopped); ``at_ns``: when the end happened,
        if the tool noticed it later (an ending module's exit), else now.

        Time is judged up to this event, not through the shutdown that follows
        (no deadline findings after the end); `check` ends its judgement there too.
        """
        self.end_reason = reason
        if self.judge is not None:
            self.judge.end(reason, at_ns)
        else:
            self.emit(rec.RunEnd(time.time_ns() if at_ns is None else at_ns, reason))

    def hold_judgement(self, horizon: Callable[[int], int]) -> None:
        """The online monitors judge no further than ``horizon(now)`` (the end, dated when it happened, cannot
        come before it), so they judge nothing of the shutdown that `check` would not."""
        if self.judge is not None:
            self.judge.hold(horizon)

    def add_finding(self, violation: Violation) -> None:
        """A finding made outside the monitors (the spec's run: outcome): in the verdict and the log."""
        assert self.judge is not None, "findings come once the run started"
        self.judge.add_finding(violation)


def warm_recorder(spec_files: Sequence[Path] = ()) -> subprocess.Popen[str]:
    """A recorder started ahead of its run: imports done, ``spec_files`` parsed, waiting for its arguments.

    Give it to one run as ``RunOptions.warm_recorder``; a run whose warm
    recorder died starts a fresh one. Its owner closes its stdin (or stops
    it) when no run will take it; it dies with its parent either way.
    """
    return process_launch.start([*python_module("astaa_deft.engine.session.recorder"), "--warm", *map(str, spec_files)],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)


def release_warm_recorder(recorder: ChildProcess | None) -> None:
    """A recorder started ahead that no run took: end of its input, and it exits."""
    if recorder is not None and recorder.stdin is not None and not recorder.stdin.closed:
        with contextlib.suppress(OSError):
            recorder.stdin.close()


def _bus_plan(spec: Spec, options: RunOptions) -> BusPlan:
    """The tool's place on the bus: a client of the running SUT (no launch), its router (star), or a client of
    a router of ours (passive); raises InputError when an attached run does not say where the SUT is."""
    listen = [_concrete(ep) for ep in spec.zenoh.endpoints]
    if not options.launch:
        # Attach to a running SUT: the user's own router or peers, as a client.
        endpoints = list(spec.zenoh.connect)
        if not endpoints:
            raise InputError(Problem(str(spec.path or "<spec>"), None, None,
                                     "--no-launch needs to know where the running SUT is",
                                     "list its router under 'zenoh: connect: [...]' in the spec"))
        return BusPlan(zc.config_dict(mode="client", connect=endpoints), listen, endpoints, router=False)
    if options.mode == RunMode.STAR:
        return BusPlan(zc.config_dict(mode="router", listen=listen), listen, listen[:1], router=False)
    return BusPlan(zc.config_dict(mode="client", connect=listen[:1]), listen, listen[:1], router=True)


def _concrete(endpoint: str) -> str:
    """Replace port 0 by a free port (Zenoh itself would too, but we must know it)."""
    proto, _, addr = endpoint.partition("/")
    host, _, port = addr.rpartition(":")
    if port == "0":
        return f"{proto}/{host}:{zc.free_port(host.strip('[]') or zc.LOOPBACK)}"
    return endpoint


def _check_writable(path: Path) -> None:
    """A log path in a missing folder is a usage error (InputError); a place that takes no file, OutputError."""
    if not path.is_dir() and not path.parent.exists():
        raise InputError(Problem(str(path), None, None, f"log path folder '{path.parent}' does not exist",
                                 "give a writable file path"))
    ready_file(Place(path, "--record"))
