"""One run of the SUT on the bus: tool session, proxy or observer, recorder, modules.

Start order: the tool's session (and the star proxy) first, then the recorder
(subscribed before any module speaks), then the modules in spec order.
Stop order is the reverse, so the recorder sees every last message and the
log is finished cleanly whatever ended the run.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import zenoh

from ..errors import InputError, Problem
from ..spec.model import Spec
from . import topology
from . import zenoh_config as zc
from .launcher import Launcher, ProcessExit
from .observer import ChannelCounter
from .processes import die_with_parent, stop_process, tail
from .proxy import StarProxy

RECORDER_READY_TIMEOUT = 20.0
DRAIN_SECONDS = 0.3  # after the modules stop, let in-flight messages reach the recorder


@dataclass
class RunOptions:
    mode: str = "star"  # "star" (man in the middle) or "passive" (observer only)
    launch: bool = True  # False: attach to an already running SUT
    record: Path | None = None
    params: dict[str, str] = field(default_factory=dict)
    command_line: list[str] = field(default_factory=list)
    run_dir: Path | None = None  # module logs and configs; a temp dir if None


class BusRun:
    def __init__(self, spec: Spec, options: RunOptions,
                 on_event: Callable[[dict], None] = lambda event: None):
        self.spec = spec
        self.options = options
        self.on_event = on_event
        self.events: list[dict] = []
        self.exits: list[ProcessExit] = []
        self.session: zenoh.Session | None = None
        self.proxy: StarProxy | None = None
        self.counter: ChannelCounter | None = None
        self.launcher: Launcher | None = None
        self.recorder: subprocess.Popen | None = None
        self.recorded: dict[str, int] = {}
        self.started_ns = 0
        self._subs: list = []
        self._tmp: tempfile.TemporaryDirectory | None = None
        self._events_pub: zenoh.Publisher | None = None
        self._lock = threading.Lock()

    # -- lifecycle ---------------------------------------------------------
    def __enter__(self) -> "BusRun":
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
        if opts.run_dir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix=f"astaa-deft-{self.spec.name}-")
            self.run_dir = Path(self._tmp.name)
        else:
            self.run_dir = opts.run_dir
            self.run_dir.mkdir(parents=True, exist_ok=True)
        if opts.record is not None:
            _check_writable(opts.record)
        listen = [_concrete(ep) for ep in self.spec.zenoh.endpoints]
        connect = [] if opts.launch else list(self.spec.zenoh.connect)
        self.tool_endpoint = listen[0]
        self.session = self._open(topology.tool_config(opts.mode, listen, connect), listen)
        self._events_pub = self.session.declare_publisher(topology.EVENTS_KEY)
        self.started_ns = time.time_ns()
        if opts.mode == "star":
            self.proxy = StarProxy(self.session, self.spec, on_undeclared=self._undeclared)
            self.proxy.start()
        else:
            self.counter = ChannelCounter(self.session, self.spec, opts.mode)
        observers = [self.tool_endpoint]
        if opts.record is not None:
            observers.append(self._start_recorder(opts.record, connect))
        self.event("run_started", mode=opts.mode, spec=self.spec.name, command_line=opts.command_line)
        if opts.launch:
            self._launch(observers)

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

    def _launch(self, observers: list[str]) -> None:
        configs = topology.module_configs(self.spec, self.options.mode, observers[0])
        if self.options.mode == "passive":
            for cfg in configs.values():  # the recorder listens too: modules connect to it directly
                cfg["connect"]["endpoints"] = observers[1:] + cfg["connect"]["endpoints"]
        files = {
            name: zc.write_config_file(cfg, self.run_dir / f"zenoh-{name}.json5") for name, cfg in configs.items()
        }
        self.launcher = Launcher(self.spec, self.run_dir, files, params=self.options.params,
                                 channel_seen=lambda ch: self.counts().get(ch, 0) > 0,
                                 on_exit=self._process_exited)
        self.launcher.start()

    def _start_recorder(self, path: Path, connect: list[str]) -> str:
        args = [sys.executable, "-m", "astaa_deft.log.recorder", "--spec", str(self.spec.path),
                "--out", str(path), "--mode", self.options.mode,
                "--meta", json.dumps({"spec": self.spec.name, "command_line": " ".join(self.options.command_line),
                                      "started_ns": str(self.started_ns)})]
        own = ""
        if self.options.mode == "star":
            args += ["--connect", self.tool_endpoint]
        else:
            own = zc.loopback_endpoint()
            args += ["--listen", own, "--connect", self.tool_endpoint]
            for ep in connect:
                args += ["--connect", ep]
        self._recorder_log = self.run_dir / "recorder.log"
        with open(self._recorder_log, "wb") as err:
            self.recorder = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=err, stdin=subprocess.DEVNULL,
                                             start_new_session=True, preexec_fn=die_with_parent, text=True)
        ready = threading.Event()
        lines: list[str] = []

        def read() -> None:
            assert self.recorder is not None and self.recorder.stdout is not None
            for line in self.recorder.stdout:
                lines.append(line.strip())
                if line.strip() == "ready":
                    ready.set()
            ready.set()

        self._recorder_reader = threading.Thread(target=read, daemon=True)
        self._recorder_reader.start()
        self._recorder_lines = lines
        if not ready.wait(RECORDER_READY_TIMEOUT) or "ready" not in lines:
            raise InputError(Problem(str(path), None, None, "the recorder did not start:\n" + tail(self._recorder_log),
                                     "check that the log path is writable"))
        return own or self.tool_endpoint

    def stop(self) -> None:
        if self.launcher is not None:
            self.launcher.stop()
        if self.session is not None and (self.launcher is not None or self.recorder is not None):
            self.event("run_stopped")
            time.sleep(DRAIN_SECONDS)
        if self.recorder is not None:
            stop_process(self.recorder, grace=30.0)
            self._recorder_reader.join(timeout=5.0)
            for line in self._recorder_lines:
                if line.startswith("{"):
                    self.recorded = json.loads(line).get("recorded", {})
            self.recorder = None
        for holder in (self.proxy, self.counter):
            if holder is not None:
                holder.stop()
        if self.session is not None:
            self.session.close()
            self.session = None
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    # -- observation -------------------------------------------------------
    def counts(self) -> dict[str, int]:
        if self.proxy is not None:
            return self.proxy.counts()
        if self.counter is not None:
            return self.counter.counts()
        return {}

    def subscribe(self, channel: str, callback: Callable[[zenoh.Sample], None]) -> None:
        """Watch a declared channel from the tool (as its producer published it)."""
        key = dict((ch.name, k) for k, ch in topology.recorded_keys(self.spec, self.options.mode))[channel]
        assert self.session is not None
        self._subs.append(self.session.declare_subscriber(key, callback))

    def crashed(self) -> list[ProcessExit]:
        return [e for e in self.exits if e.abnormal]

    def alive(self) -> list[str]:
        return self.launcher.alive() if self.launcher else []

    # -- events ------------------------------------------------------------
    def event(self, kind: str, **fields) -> dict:
        body = {"kind": kind, "time_ns": time.time_ns(), **fields}
        with self._lock:
            self.events.append(body)
        if self._events_pub is not None:
            self._events_pub.put(json.dumps(body, default=str))
        self.on_event(body)
        return body

    def _process_exited(self, exit_: ProcessExit) -> None:
        self.exits.append(exit_)
        self.event("process_exit", module=exit_.module, pid=exit_.pid, returncode=exit_.returncode,
                   signal=exit_.signal, during_shutdown=exit_.during_shutdown, abnormal=exit_.abnormal,
                   stderr_tail=exit_.stderr_tail)

    def _undeclared(self, module: str, key: str) -> None:
        self.event("undeclared_key", module=module, key=key,
                   note="forwarded to every other module; declare it under 'channels' to route it precisely")


def _concrete(endpoint: str) -> str:
    """Replace port 0 by a free port (Zenoh itself would too, but we must know it)."""
    proto, _, addr = endpoint.partition("/")
    host, _, port = addr.rpartition(":")
    if port == "0":
        return f"{proto}/{host}:{zc.free_port(host.strip('[]') or zc.LOOPBACK)}"
    return endpoint


def _check_writable(path: Path) -> None:
    problem = None
    if path.is_dir():
        problem = "is a directory"
    elif not path.parent.exists():
        problem = f"folder '{path.parent}' does not exist"
    else:
        try:
            with open(path, "ab"):
                pass
        except OSError as exc:
            problem = f"cannot be written: {exc.strerror}"
    if problem:
        raise InputError(Problem(str(path), None, None, f"log path {problem}", "give a writable file path"))
