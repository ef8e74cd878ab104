"""Start the spec's modules as subprocesses, watch them, and stop exactly them.

Each module runs in its own process group, so its children go with it; a
reaper process ends those groups if the tool dies without cleaning up, so no
run leaves orphans. Only the process groups started here are signalled.
"""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Callable, Mapping

from astaa_deft.io.output_place import open_new, write_atomic
from astaa_deft.model.errors import InputError, Problem
from astaa_deft.model.patterns import UserPattern, compile_user_pattern
from astaa_deft.model.records import ProcessExit
from astaa_deft.model.sut import Module, Spec
from astaa_deft.engine.bus import process_launch
from astaa_deft.engine.bus.processes import python_module, signal_group, tail
import contextlib



class ModuleNotReady(InputError):
    """A module still running but not ready in time (exit 2: most often a readiness condition to fix)."""

    def __init__(self, problem: Problem, module: str, detail: str):
        super().__init__(problem)
        self.module = module
        self.detail = detail


class ModuleCrashedWhileStarting(InputError):
    """A module that exited while starting: a finding about the SUT, exit code 1 like any module crash.

    An InputError still, so every caller that turns "the run could not start"
    into a message keeps doing so; only the CLI's exit code differs.
    """

    exit_code = 1


@dataclass(kw_only=True)
class RunningModule:
    module: Module
    process: subprocess.Popen
    log_path: Path
    started_ns: int
    exit: ProcessExit | None = None


def output_file(run_dir: Path, module: str) -> Path:
    """Where a module's stdout and stderr go (one file, in the order written)."""
    return run_dir / f"{module}.log"


@dataclass(kw_only=True)
class Launcher:
    """Launch the spec's modules with the given per-module Zenoh config files."""

    spec: Spec
    run_dir: Path
    config_files: Mapping[str, Path]
    params: Mapping[str, str] = field(default_factory=dict)
    channel_seen: Callable[[str], bool] = lambda _name: False
    on_exit: Callable[[ProcessExit], None] = lambda _exit: None

    def __post_init__(self) -> None:
        self.running: dict[str, RunningModule] = {}
        self.exits: queue.Queue[ProcessExit] = queue.Queue()
        self._stopping = threading.Event()
        self._reaper: subprocess.Popen | None = None

    # -- start ---------------------------------------------------------------
    def start(self, on_ready: Callable[[str], None] = lambda _m: None) -> None:
        """Start every module in spec order, each after the previous one is ready."""
        # The reaper must outlive the tool (ending the groups is its job): no parent-death signal for it.
        self._reaper = process_launch.start(python_module("astaa_deft.engine.bus.reaper"), stdin=subprocess.PIPE,
                                            text=True, die_with_tool=False)
        try:
            for module in self.spec.modules:
                self._start_one(module)
                self._wait_ready(module)
                on_ready(module.name)
        except BaseException:
            self.stop()
            raise

    def placeholders(self, module: Module) -> dict[str, str]:
        spec_dir = self.spec.path.parent if self.spec.path else Path.cwd()
        values = dict(self.spec.params)
        values.update(self.params)
        values.update(
            python=sys.executable,
            zenoh_config=str(self.config_files[module.name]),
            module=module.name,
            run_dir=str(self.run_dir),
            spec_dir=str(spec_dir),
        )
        return values

    def _start_one(self, module: Module) -> None:
        values = self.placeholders(module)
        argv = [part.format_map(values) for part in module.command]
        env = dict(os.environ)
        env.update({k: v.format_map(values) for k, v in module.env.items()})
        config = str(self.config_files[module.name])
        env["ZENOH_CONFIG"] = config
        env["ZENOH_SESSION_CONFIG_URI"] = config  # ROS 2 rmw_zenoh
        env.setdefault("PYTHONUNBUFFERED", "1")
        log_path = output_file(self.run_dir, module.name)
        log = open_new(log_path, "--run-dir")  # the module writes to it for its whole life; closed at its exit
        try:
            # Its own process group (process_launch.start): stop (or the reaper) takes its children too.
            process = process_launch.start(argv, cwd=str(module.cwd) if module.cwd else None, env=env,
                                           stdout=log, stderr=subprocess.STDOUT)
        except FileNotFoundError:
            raise InputError(Problem(
                str(self.spec.path or "<spec>"), None, None,
                f"module '{module.name}': command '{argv[0]}' not found",
                "install it or fix 'command' in the spec",
            )) from None
        except PermissionError:
            raise InputError(Problem(
                str(self.spec.path or "<spec>"), None, None,
                f"module '{module.name}': command '{argv[0]}' is not executable", "chmod +x it or fix 'command'",
            )) from None
        finally:
            log.close()
        running = RunningModule(module=module, process=process, log_path=log_path, started_ns=time.time_ns())
        self.running[module.name] = running
        self._tell_reaper(str(process.pid))
        # What we started, by id, for whoever has to check or clean up after us.
        write_atomic(self.run_dir / "processes.json", json.dumps(self.pids(), indent=1))
        threading.Thread(target=self._watch, args=(running,), name=f"watch-{module.name}", daemon=True).start()

    def _wait_ready(self, module: Module) -> None:
        ready = module.ready
        if ready.channel is None and ready.log is None:
            end = time.monotonic() + (ready.delay or 0.0)
            while time.monotonic() < end:
                self._raise_if_exited(module)
                time.sleep(0.02)
            self._raise_if_exited(module)
            return
        if ready.channel is not None:
            is_ready, what = (lambda: self.channel_seen(ready.channel)), f"no message on '{ready.channel}'"
        else:
            assert ready.log is not None  # the spec loader gives every readiness a channel, a log line or a delay
            pattern = compile_user_pattern(ready.log)  # checked by the spec loader: RE2, linear time
            log_path = self.running[module.name].log_path
            is_ready, what = (lambda: _log_matches(log_path, pattern)), f"no output line matching '{ready.log}'"
        deadline = time.monotonic() + ready.timeout
        while not is_ready():
            self._raise_if_exited(module)
            if time.monotonic() > deadline:
                detail = f"{what} within {ready.timeout:g} s"
                raise ModuleNotReady(Problem(
                    str(self.spec.path or "<spec>"), None, None, f"module '{module.name}' not ready: {detail}",
                    f"check {self.running[module.name].log_path} or raise 'ready.timeout'",
                ), module.name, detail)
            time.sleep(0.02)

    def _raise_if_exited(self, module: Module) -> None:
        running = self.running[module.name]
        code = running.process.poll()
        if code is not None:
            log_tail = tail(running.log_path)
            deadline = time.monotonic() + 2.0  # its watcher logs the exit as an event (the verdict's finding)
            while running.exit is None and time.monotonic() < deadline:
                time.sleep(0.01)
            raise ModuleCrashedWhileStarting(Problem(
                str(self.spec.path or "<spec>"), None, None,
                f"module '{module.name}' exited with code {code} while starting"
                + (f":\n{log_tail}" if log_tail else ""),
                f"run its command by hand to see why (log: {running.log_path})",
            ))

    # -- watch ---------------------------------------------------------------
    def _watch(self, running: RunningModule) -> None:
        code = running.process.wait()
        sig = signal.Signals(-code).name if code < 0 and -code in signal.valid_signals() else None
        event = ProcessExit(
            module=running.module.name,
            pid=running.process.pid,
            returncode=code,
            signal=sig,
            time_ns=time.time_ns(),
            during_shutdown=self._stopping.is_set(),
            stderr_tail=tail(running.log_path) if code != 0 else "",
        )
        running.exit = event
        self.exits.put(event)
        self.on_exit(event)

    def alive(self) -> list[str]:
        return [name for name, r in self.running.items() if r.process.poll() is None]

    def pids(self) -> dict[str, int]:
        return {name: r.process.pid for name, r in self.running.items()}

    # -- stop ----------------------------------------------------------------
    def stop(self, grace: float = 5.0) -> None:
        """SIGTERM each module's process group, SIGKILL whatever is left after `grace` s."""
        self._stopping.set()
        for r in reversed(list(self.running.values())):
            signal_group(r.process, signal.SIGTERM)
        deadline = time.monotonic() + grace
        for r in self.running.values():
            with contextlib.suppress(subprocess.TimeoutExpired):
                r.process.wait(timeout=max(0.0, deadline - time.monotonic()))
        for r in self.running.values():
            # The group may outlive its leader (a module's own children): kill it whole.
            signal_group(r.process, signal.SIGKILL)
            with contextlib.suppress(subprocess.TimeoutExpired):
                r.process.wait(timeout=2.0)
        if self._reaper is not None:
            self._tell_reaper("done")
            try:
                if self._reaper.stdin is not None:
                    self._reaper.stdin.close()
                self._reaper.wait(timeout=5.0)
            except (OSError, subprocess.TimeoutExpired):
                pass
            self._reaper = None

    def _tell_reaper(self, line: str) -> None:
        if self._reaper is not None and self._reaper.stdin is not None:
            try:
                self._reaper.stdin.write(line + "\n")
                self._reaper.stdin.flush()
            except OSError:
                pass


def _log_matches(path: Path, pattern: UserPattern) -> bool:
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return False
    return any(pattern.search(line) for line in text.splitlines())
