"""The run's modules part: the SUT's modules launched in spec order, their exits and their output lines."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from astaa_deft.engine.bus import topology
from astaa_deft.engine.bus import zenoh_config as zc
from astaa_deft.engine.bus.launcher import Launcher, ModuleNotReady, output_file
from astaa_deft.model.records import ProcessExit
from astaa_deft.engine.session.judge import Judge
from astaa_deft.engine.session.module_output import ModuleOutputFollower
from astaa_deft.engine.session.options import RunOptions
from astaa_deft.engine.session.parts import EventLog, RunPart
from astaa_deft.engine.session.transport import Transport
from astaa_deft.io.log import records as rec
from astaa_deft.model.sut import Spec


@dataclasses.dataclass(frozen=True)
class ModulesPlace:
    """Where the modules run: the run directory (configs, output files) and the bus endpoint they connect to."""

    run_dir: Path
    bus_endpoint: str


class Modules(RunPart):
    """Launches every module (each waits for the previous one to be ready) and follows its output.

    Each exit is logged and judged (``exits`` only grows, from the
    launcher's watcher thread); a module not ready in time is a finding,
    then ``start`` raises ``ModuleNotReady``. ``close`` stops the modules,
    then reads their last lines.
    """

    def __init__(self, spec: Spec, options: RunOptions, place: ModulesPlace, *, transport: Transport,
                 judge: Judge, events: EventLog):
        self._spec, self._options, self._place = spec, options, place
        self._transport, self._judge, self._events = transport, judge, events
        self.launcher: Launcher | None = None
        self.output: ModuleOutputFollower | None = None  # the modules' output lines, as they come
        self.exits: list[ProcessExit] = []

    def start(self) -> None:
        run_dir = self._place.run_dir
        configs = topology.module_configs(self._spec, self._options.mode, self._place.bus_endpoint)
        files = {name: zc.write_config_file(cfg, run_dir / f"zenoh-{name}.json5") for name, cfg in configs.items()}
        self.launcher = Launcher(spec=self._spec, run_dir=run_dir, config_files=files, params=self._options.params,
                                 channel_seen=lambda ch: self._transport.counts().get(ch, 0) > 0,
                                 on_exit=self._exited)
        self.output = ModuleOutputFollower({m.name: output_file(run_dir, m.name) for m in self._spec.modules},
                                           self._line)
        self.output.start()
        try:
            self.launcher.start()
        except ModuleNotReady as exc:
            # Alive but silent: a hang as far as the CRASH scale goes. Logged so the run's verdict
            # is no Pass (the exit code stays 2: most often the readiness condition needs fixing).
            self._judge.not_ready(exc)
            raise

    def close(self) -> None:
        if self.launcher is not None:
            self.launcher.stop()
        if self.output is not None:
            self.output.stop()  # the modules' last lines (logged; judged only up to the stop)
            self.output = None

    def alive(self) -> list[str]:
        """The modules still running."""
        return self.launcher.alive() if self.launcher is not None else []

    def crashed(self) -> list[ProcessExit]:
        """The abnormal exits so far."""
        return [e for e in self.exits if e.abnormal]

    def _line(self, module: str, text: str, time_ns: int) -> None:
        self._events.emit(rec.ModuleLogLine(time_ns, module, "output", text))
        self._judge.module_line(module, text, time_ns)

    def _exited(self, exit_: ProcessExit) -> None:
        run_section = self._spec.run
        if run_section is not None and run_section.exit_end(exit_.module) is not None and not exit_.during_shutdown:
            # The spec says this module's exit *is* the run's end: not a crash; its code is the outcome
            # (session/run_end.py turns a failing code into a finding).
            exit_ = dataclasses.replace(exit_, during_shutdown=True)
        self.exits.append(exit_)
        self._judge.process_exit(exit_)
        self._events.emit(exit_)
