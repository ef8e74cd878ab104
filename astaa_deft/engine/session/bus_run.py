"""One run of the SUT on the bus: tool session, proxy or observer, recorder, modules.

The session's parts; :func:`run_session` drives them.

Start order: the tool's session (and the star proxy) first, then the recorder
(subscribed before any module speaks), then the modules in spec order.
Stop order is the reverse, so the recorder sees every last message and the
log is finished cleanly whatever ended the run.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path
from collections.abc import Callable, Sequence

import zenoh

from astaa_deft.model.errors import InputError, Problem
from astaa_deft.io.inputfile import SPEC, read_input
from astaa_deft.io.output_place import Place, check_temp_dir, ready_dir, ready_file
from astaa_deft.model.sut import Spec
from astaa_deft.engine.bus import topology
from astaa_deft.engine.bus import zenoh_config as zc
from astaa_deft.io.log import records as rec
from astaa_deft.engine.monitor.online import OnlineMonitors
from astaa_deft.engine.bus.launcher import Launcher, ModuleNotReady, output_file
from astaa_deft.model.records import ProcessExit, Verdict
from astaa_deft.engine.monitor.verdict import RunVerdict
from astaa_deft.engine.monitor.violation import Violation
from astaa_deft.engine.bus.observer import ChannelCounter
from astaa_deft.engine.bus import process_launch
from astaa_deft.engine.bus.processes import ChildProcess, python_module, stop_process, tail
from astaa_deft.engine.bus.interception import InterceptionBridge
from astaa_deft.engine.bus.proxy import StarProxy, plain_forwarder
from astaa_deft.engine.session.module_output import ModuleOutputFollower
from astaa_deft.engine.session.options import RunOptions

HELPER_READY_TIMEOUT = 20.0
DRAIN_SECONDS = 0.3  # after the modules stop, let in-flight messages reach the tool's subscribers
SUBSCRIBED_LIMIT = 2.0  # for the router to see the recorder's subscribers after its 'ready'
CATCH_UP_LIMIT = 15.0  # at most this long for a recorder that fell behind to read its backlog
RECORDER_CAUGHT_UP = "caught up"  # the recorder's line once the run_stopped event (and all before it) arrived


class BusRun:
    def __init__(self, spec: Spec, options: RunOptions,
                 on_event: Callable[[rec.Record], None] | None = None):
        self.spec = spec
        self.options = options
        self.on_event: Callable[[rec.Record], None] = on_event or (lambda event: None)
        self._listening = on_event is not None  # mutations become typed records only for a listener
        self.events: list[rec.Record] = []
        self.exits: list[ProcessExit] = []
        self.session: zenoh.Session | None = None
        self.proxy: StarProxy | None = None
        self.counter: ChannelCounter | None = None
        self.launcher: Launcher | None = None
        self.output: ModuleOutputFollower | None = None  # the modules' output lines, as they come
        self._judged_until_ns = 2**63  # set when the run begins to stop
        self.recorder: ChildProcess | None = None
        self.recorded: dict[str, int] = {}
        self.started_ns = 0
        self.interceptor_epoch_ns: int | None = None  # the interceptor's clock origin, on the log's clock
        self._subs: list = []
        self._tmp: tempfile.TemporaryDirectory | None = None
        self._events_pub: zenoh.Publisher | None = None
        self._lock = threading.Lock()
        self._helpers: list[ChildProcess] = []  # recorder, bus router: ours to stop
        self._helper_output: dict[int, tuple[threading.Thread, list[str]]] = {}
        self._helper_names: dict[int, str] = {}  # pid → "recorder" | "bus router"
        self.lost: str = ""  # why a helper of ours stopped mid-run: the run is not fully observed or recorded
        self.bus_endpoints: list[str] = []
        self.interception: InterceptionBridge | None = None
        self.policies: list[rec.PolicyApplicationsRecord] = []  # per policy of the test case, at the end
        self.monitors: OnlineMonitors | None = None
        self.verdict: RunVerdict | None = None  # the CRASH-scale verdict, once stopped
        self.violations: list[rec.Violation] = []
        self.stop_requested = threading.Event()  # --stop-on-violation
        self.end_reason = ""
        self.recorder_finished = False  # the recorder reported its counts and exited cleanly

    # -- lifecycle ---------------------------------------------------------
    def __enter__(self) -> BusRun:
        try:
            self.start()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def start(self) -> None:
        opts = self.options
        if opts.interceptor is not None and opts.mode != "star":
            raise InputError("a policy needs the star: interception cannot run with --passive")
        # Both output places are checked before anything starts (OutputError: the place cannot take files).
        if opts.record is not None:
            _check_writable(opts.record)
        if opts.run_dir is None:
            check_temp_dir()
            self._tmp = tempfile.TemporaryDirectory(prefix=f"astaa-deft-{self.spec.name}-")
            self.run_dir = Path(self._tmp.name)
        else:
            # Absolute: the paths handed to modules (ZENOH_CONFIG…) must hold from a module's own cwd too.
            self.run_dir = ready_dir(Place(opts.run_dir.resolve(), "--run-dir"))
        listen = [_concrete(ep) for ep in self.spec.zenoh.endpoints]
        if not opts.launch:
            # Attach to a running SUT: the user's own router or peers, as a client.
            self.bus_endpoints = list(self.spec.zenoh.connect)
            if not self.bus_endpoints:
                raise InputError(Problem(str(self.spec.path or "<spec>"), None, None,
                                         "--no-launch needs to know where the running SUT is",
                                         "list its router under 'zenoh: connect: [...]' in the spec"))
            tool_cfg = zc.config_dict(mode="client", connect=self.bus_endpoints)
        elif opts.mode == "star":
            self.bus_endpoints = listen[:1]
            tool_cfg = zc.config_dict(mode="router", listen=listen)
        else:
            self.bus_endpoints = listen[:1]
            self.bus_router = self._spawn_ready("bus router", [*python_module("astaa_deft.engine.bus.router"),
                                                          *[a for ep in listen for a in ("--listen", ep)]])
            tool_cfg = zc.config_dict(mode="client", connect=self.bus_endpoints)
        self.session = self._open(tool_cfg, listen)
        self._events_pub = self.session.declare_publisher(topology.EVENTS_KEY)
        self.started_ns = time.time_ns()
        if opts.mode == "star":
            make_forwarder = plain_forwarder
            if opts.interceptor is not None:
                # One instant on both clocks: event times count from it, the log says where it is.
                epoch_monotonic, self.interceptor_epoch_ns = time.monotonic(), time.time_ns()
                self.interception = InterceptionBridge(self.session, opts.interceptor, epoch_monotonic,
                                                       on_mutation=self._mutated if self._listening else None)
                make_forwarder = self.interception.make_forwarder
            self.proxy = StarProxy(self.session, self.spec, on_undeclared=self._undeclared,
                                   make_forwarder=make_forwarder)
            self.proxy.start()
            if self.interception is not None:
                self.interception.start()
        else:
            self.counter = ChannelCounter(self.session, self.spec, opts.mode)
        if opts.record is not None:
            self._start_recorder(opts.record)
            self._wait_recorder_subscribed()
        started = self.emit(rec.RunStarted(time.time_ns(), opts.mode, self.spec.name, tuple(opts.command_line),
                                           self.interceptor_epoch_ns))
        self.monitors = OnlineMonitors(self.spec, started.time_ns, self._violated)
        intercepted = self.interception.targets if self.interception is not None else set()
        self.monitors.subscribe(self.session, [(k, ch.name) for k, ch in topology.observed_keys(self.spec, opts.mode)
                                               if ch.name not in intercepted])
        if self.interception is not None:
            self.interception.on_delivered = self.monitors.feed
        if opts.launch:
            self._launch()

    def _open(self, cfg: dict, listen: list[str]) -> zenoh.Session:
        try:
            return zc.open_session(cfg, self.spec.zenoh.config_file)
        except zenoh.ZError as exc:
            where = str(self.spec.path or "<spec>")
            raise InputError(Problem(
                where, None, None,
                f"cannot open the tool's Zenoh session on {', '.join(listen)}: {exc}",
                "the port may be in use: set 'zenoh.endpoints' to another port, or port 0 for a free one",
            )) from None

    def _launch(self) -> None:
        configs = topology.module_configs(self.spec, self.options.mode, self.bus_endpoints[0])
        files = {
            name: zc.write_config_file(cfg, self.run_dir / f"zenoh-{name}.json5") for name, cfg in configs.items()
        }
        self.launcher = Launcher(self.spec, self.run_dir, files, params=self.options.params,
                                 channel_seen=lambda ch: self.counts().get(ch, 0) > 0,
                                 on_exit=self._process_exited)
        self.output = ModuleOutputFollower({m.name: output_file(self.run_dir, m.name) for m in self.spec.modules},
                                           self._module_line)
        self.output.start()
        try:
            self.launcher.start()
        except ModuleNotReady as exc:
            # Alive but silent: a hang as far as the CRASH scale goes. Logged so the run's verdict
            # is no Pass (the exit code stays 2: most often the readiness condition needs fixing).
            self._not_ready(exc)
            raise

    def _start_recorder(self, path: Path) -> None:
        meta = {"spec": self.spec.name, "command_line": " ".join(self.options.command_line),
                "started_ns": str(self.started_ns),
                "params": json.dumps({**self.spec.params, **self.options.params}, sort_keys=True)}
        # The spec travels as its text on stdin: the recorder reads the session's spec, not a file.
        args = ["--out", str(path),
                "--spec-name", self.spec.path.name if self.spec.path is not None else f"{self.spec.name}.yaml",
                "--mode", self.options.mode, "--meta", json.dumps(meta)]
        for ep in self.bus_endpoints:
            args += ["--connect", ep]
        if self.interception is not None:
            for name in sorted(self.interception.targets):
                args += ["--intercepted", name]
        for name, file in self.options.attachments.items():
            args += ["--attach", f"{name}={file}"]
        spec_text = self.spec.source_text or \
            (read_input(self.spec.path, SPEC).decode("utf-8") if self.spec.path is not None else "")
        warm = self.options.warm_recorder
        if warm is not None and warm.poll() is None:  # started ahead (imports done): hand it its arguments
            args = ["--log-file", str(self.run_dir / "recorder.log"), *args]
            self.recorder = self._spawn_ready("recorder", args, error_file=path,
                                              stdin_text=json.dumps(args) + "\n" + spec_text, warm=warm)
        else:
            self.recorder = self._spawn_ready("recorder", [*python_module("astaa_deft.engine.session.recorder"), *args],
                                              error_file=path, stdin_text=spec_text)

    def _wait_recorder_subscribed(self) -> None:
        """The recorder says 'ready' once it declared its subscribers; the router may learn of them a moment
        later, and an event published in between (run_started) would miss the log. Wait until our events
        publisher sees a subscriber (bounded: a Zenoh that does not report matching must not stall runs)."""
        assert self._events_pub is not None and self.recorder is not None
        deadline = time.monotonic() + SUBSCRIBED_LIMIT
        while time.monotonic() < deadline and self.recorder.poll() is None:
            try:
                # zenoh's stub types Publisher.matching_status as bool; at run time it is a MatchingStatus.
                if self._events_pub.matching_status.matching:  # type: ignore[attr-defined]
                    return
            except zenoh.ZError:
                return
            time.sleep(0.005)

    def _spawn_ready(self, name: str, args: list[str], error_file: Path | None = None,
                     stdin_text: str | None = None, warm: ChildProcess | None = None) -> ChildProcess:
        """Start one of the tool's own helper processes (``stdin_text`` on its stdin) and wait for its 'ready' line.

        ``warm``: the helper was started ahead (:func:`warm_recorder`) and is waiting for ``stdin_text``."""
        log_path = self.run_dir / f"{name.split()[-1]}.log"
        proc: ChildProcess
        if warm is not None:
            proc = warm
        else:
            with open(log_path, "wb") as err:
                proc = process_launch.start(args, stdout=subprocess.PIPE, stderr=err, text=True,
                                            stdin=subprocess.DEVNULL if stdin_text is None else subprocess.PIPE)
        self._helpers.append(proc)
        if stdin_text is not None:
            assert proc.stdin is not None
            try:
                proc.stdin.write(stdin_text)
                proc.stdin.close()
            except BrokenPipeError:  # it died at once: the ready check below says why
                pass
        self._helper_names[proc.pid] = name
        ready = threading.Event()
        lines: list[str] = []

        def read() -> None:
            assert proc.stdout is not None
            for line in proc.stdout:
                lines.append(line.strip())
                if line.strip() == "ready":
                    ready.set()
            ready.set()

        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        self._helper_output[proc.pid] = (reader, lines)
        if not ready.wait(HELPER_READY_TIMEOUT) or "ready" not in lines:
            raise InputError(Problem(str(error_file or self.spec.path), None, None,
                                     f"the {name} did not start:\n{tail(log_path)}",
                                     "see the message above" + (" (is the log path writable?)" if error_file else "")))
        return proc

    def stop(self) -> None:
        if self.interception is not None:
            self.interception.stop()  # release held and delayed messages while consumers still listen
            self._log_applications(self.interception.t0)
        stopping = self.emit(rec.RunStopping(time.time_ns())) if self.monitors is not None else None
        self._judged_until_ns = stopping.time_ns if stopping is not None else time.time_ns()
        if self.monitors is not None and stopping is not None:
            # Judged up to the stop, as `check` judges the log: the silence of modules being stopped
            # (one slow to exit, a loaded machine) is the tool's doing, not a hang of the SUT.
            self.verdict = self.monitors.finish(stopping.time_ns)
            verdict = self.verdict
            self.emit(rec.VerdictRecord(time.time_ns(), verdict.klass, verdict.summary, verdict.first, verdict.reasons))
            self.monitors = None
        if self.launcher is not None:
            self.launcher.stop()
        if self.output is not None:
            self.output.stop()  # the modules' last lines (logged; judged only up to the stop)
            self.output = None
        if self.session is not None and (self.launcher is not None or self.recorder is not None):
            self.emit(rec.RunStopped(time.time_ns()))
            time.sleep(DRAIN_SECONDS)
            self._wait_recorder_caught_up()
        if self.recorder is not None:
            stop_process(self.recorder, grace=30.0)
            reader, lines = self._helper_output[self.recorder.pid]
            reader.join(timeout=5.0)
            for line in lines:
                if line.startswith("{"):
                    self.recorded = json.loads(line).get("recorded", {})
                    self.recorder_finished = self.recorder.returncode == 0
            self.recorder = None
        for holder in (self.proxy, self.counter):
            if holder is not None:
                holder.stop()
        if self.session is not None:
            self.session.close()
            self.session = None
        for proc in self._helpers:  # the bus router last: everyone else has let go of it
            stop_process(proc, grace=5.0)
        self._helpers = []
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def _wait_recorder_caught_up(self) -> None:
        """A recorder behind (a burst, a slow disk) still holds messages in its socket: stopping it now would
        lose them. It says when the run_stopped event has arrived, i.e. everything sent before it. Not
        waited for when the bus router is lost: nothing reaches the recorder any more."""
        if self.recorder is None or self.helper_lost():
            return
        _, lines = self._helper_output[self.recorder.pid]
        deadline = time.monotonic() + CATCH_UP_LIMIT
        while (RECORDER_CAUGHT_UP not in lines and self.recorder.poll() is None
               and time.monotonic() < deadline):
            time.sleep(0.02)

    # -- observation -------------------------------------------------------
    def counts(self) -> dict[str, int]:
        if self.proxy is not None:
            return self.proxy.counts()
        if self.counter is not None:
            return self.counter.counts()
        return {}

    def subscribe(self, channel: str, callback: Callable[[zenoh.Sample], None]) -> None:
        """Watch a declared channel from the tool (as its producer published it)."""
        key = dict((ch.name, k) for k, ch in topology.observed_keys(self.spec, self.options.mode))[channel]
        assert self.session is not None
        self._subs.append(self.session.declare_subscriber(key, callback))

    def helper_lost(self) -> str:
        """Why the recorder or the bus router stopped before the run did ("" while both run).

        Either loss ends the run: without its recorder the log is incomplete,
        without its router nothing more of the bus is seen; no verdict can then
        be a Pass. Noted once in the log (if it can still be written) and kept
        in ``lost``.
        """
        if self.lost:
            return self.lost
        for proc in self._helpers:
            code = proc.poll()
            if code is None:
                continue
            how = f"killed by {signal.Signals(-code).name}" if code < 0 and -code in signal.valid_signals() \
                else f"exit code {code}"
            name = self._helper_names.get(proc.pid, "helper")
            why = tail(self.run_dir / f"{name.split()[-1]}.log", lines=3).strip()
            self.lost = f"the {name} stopped ({how})" + (f": {why}" if why else "")
            return self.lost
        return ""

    def crashed(self) -> list[ProcessExit]:
        return [e for e in self.exits if e.abnormal]

    def alive(self) -> list[str]:
        return self.launcher.alive() if self.launcher else []

    # -- events ------------------------------------------------------------
    def emit(self, record: rec.Record) -> rec.Record:
        """Log one event (the recorder writes what the tool publishes) and hand it to ``on_event``."""
        with self._lock:
            self.events.append(record)
        if self._events_pub is not None:
            self._events_pub.put(rec.to_json_text(record))
        self.on_event(record)
        return record

    def end(self, reason: str) -> None:
        """Say in the log why the run ends (before the modules are stopped).

        Time is judged up to this event, not through the shutdown that follows
        (no deadline findings after the end); `check` ends its judgement there too.
        """
        self.end_reason = reason
        ended = self.emit(rec.RunEnd(time.time_ns(), reason))
        if self.monitors is not None:
            self.monitors.end_at(ended.time_ns)

    def add_finding(self, violation) -> None:
        """A finding made outside the monitors (the spec's run: outcome): in the verdict and the log."""
        if self.monitors is not None:
            self.monitors.set.add_finding(violation)
        self._violated(violation)

    def _violated(self, violation) -> None:
        self.violations.append(violation)
        self.emit(violation)
        if self.options.stop_on_violation:
            self.stop_requested.set()

    def _module_line(self, module: str, text: str, time_ns: int) -> None:
        self.emit(rec.ModuleLogLine(time_ns, module, "output", text))
        monitors = self.monitors
        # Lines read after the run began to stop are logged, not judged (offline, `check` does the same).
        if monitors is not None and monitors.wants_log_lines() and time_ns <= self._judged_until_ns:
            monitors.log_line(module, text, time_ns)

    def _process_exited(self, exit_: ProcessExit) -> None:
        run_section = self.spec.run
        if run_section is not None and run_section.exit_end(exit_.module) is not None and not exit_.during_shutdown:
            # The spec says this module's exit *is* the run's end: not a crash; its code is the outcome
            # (session/run_end.py turns a failing code into a finding).
            exit_ = dataclasses.replace(exit_, during_shutdown=True)
        self.exits.append(exit_)
        if self.monitors is not None:
            self.monitors.process_exit(exit_.module, exit_.returncode, exit_.signal, exit_.time_ns,
                                       exit_.during_shutdown, exit_.stderr_tail)
        self.emit(exit_)

    def _not_ready(self, exc: ModuleNotReady) -> None:
        if self.monitors is None:
            return
        found = Violation("(module start)", "ready", "high", time.time_ns(), None, None, None,
                          f"module '{exc.module}' not ready: {exc.detail}", Verdict.RESTART, exc.module)
        self.monitors.set.violations.append(found)  # the verdict is the monitors' own: they must count it
        self._violated(found)

    def _log_applications(self, t0: float) -> None:
        """One event per policy: what it touched, and why it touched nothing if so (a window closed idle)."""
        report = getattr(self.options.interceptor, "applications", None)
        if report is None:
            return
        for app in report(time.monotonic() - t0):
            record = rec.decode({"kind": rec.PolicyApplicationsRecord.kind, "time_ns": time.time_ns(),
                                 **app.to_json()})
            assert isinstance(record, rec.PolicyApplicationsRecord)
            self.policies.append(record)
            self.emit(record)

    def _mutated(self, event) -> None:
        # Not re-published: the interception's own record (with the original) is in the log already.
        self.on_event(rec.MutationRecord.of(event, time.time_ns()))

    def _undeclared(self, module: str, key: str) -> None:
        note = "forwarded to every other module; declare it under 'channels' to route it precisely"
        self.emit(rec.UndeclaredKey(time.time_ns(), module, key, note))


def warm_recorder(spec_files: Sequence[Path] = ()) -> subprocess.Popen:
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
