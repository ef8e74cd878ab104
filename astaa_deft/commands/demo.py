"""`astaa-deft demo`: the bundled driving stack, through the proxy, recorded and summarised."""

from __future__ import annotations

import json
import threading
from importlib import resources
from pathlib import Path

from ..bus.run import RunOptions
from ..log.reader import read_log
from ..log.summary import format_info
from ..spec.loader import load_spec
from .console import say
from .proxy import run_bus

DEFAULT_TIME_LIMIT = 40.0


def demo_spec_path() -> Path:
    return Path(str(resources.files("astaa_deft") / "data" / "specs" / "demo_av.yaml"))


class StatusWatch:
    """The simulator's latest status message, as the tool saw it."""

    def __init__(self) -> None:
        self.latest: dict = {}
        self.collision: dict | None = None
        self.goal = False
        self._lock = threading.Lock()

    def on_sample(self, sample) -> None:
        try:
            msg = json.loads(sample.payload.to_bytes())
        except ValueError:
            return
        with self._lock:
            self.latest = msg
            if msg.get("collision") and self.collision is None:
                self.collision = msg
            if msg.get("goal_reached"):
                self.goal = True

    def finished(self, _run) -> str | None:
        if self.collision is not None:
            return "collision"
        if self.goal:
            return "goal reached"
        return None


def run(scenario: str, duration: float | None, defects: bool, passive: bool, record: Path | None,
        command_line: list[str]) -> int:
    spec = load_spec(demo_spec_path())
    if record is None:
        record = Path("astaa-deft-demo") / f"{Path(scenario).stem}.mcap"
        record.parent.mkdir(parents=True, exist_ok=True)
    params = {"scenario": scenario, "defects": "on" if defects else "off"}
    options = RunOptions(mode="passive" if passive else "star", record=record, params=params,
                         command_line=command_line)
    watch = StatusWatch()
    say(f"demo: scenario '{scenario}', defects {'on' if defects else 'off'}, "
        f"{'passive' if passive else 'star'} proxy, log {record}")
    outcome = run_bus(spec, options, duration or DEFAULT_TIME_LIMIT, until=watch.finished,
                      on_start=lambda r: r.subscribe("status", watch.on_sample))
    st = watch.latest
    say("")
    say("== summary ==")
    say(f"stopped: {outcome.reason} after {outcome.seconds:.1f} s wall, sim time {st.get('sim_time', 0):.1f} s")
    say(f"goal reached: {'yes' if watch.goal else 'no'}")
    if watch.collision is not None:
        say(f"collision: yes, with {watch.collision.get('collision_with', '?')} "
            f"at sim time {watch.collision.get('sim_time', 0):.1f} s")
    else:
        say("collision: no")
    for c in outcome.crashes:
        say(f"crash: {c.describe()}")
    say("")
    say(format_info(read_log(record)))
    ok = watch.goal and watch.collision is None and not outcome.crashes
    return 0 if ok else 1
