"""The simulator's status channel as the tool saw it: goal, collision, clearance (the run: section ends runs)."""

from __future__ import annotations

import json
import math
import threading
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the command line imports this module; zenoh loads only when a run starts
    import zenoh


class StatusWatch:
    """The simulator's latest status message, as the tool saw it (done: goal, collision or time limit)."""

    def __init__(self) -> None:
        self.latest: dict = {}
        self.collision: dict | None = None
        self.goal = False
        self.done = False
        self.min_clearance = math.inf
        self._lock = threading.Lock()

    def on_sample(self, sample: zenoh.Sample) -> None:
        try:
            msg = json.loads(sample.payload.to_bytes())
        except ValueError:
            return
        with self._lock:
            self.latest = msg
            if msg.get("collision") and self.collision is None:
                self.collision = msg
            self.goal = self.goal or bool(msg.get("goal_reached"))
            self.done = self.done or bool(msg.get("done"))
            clearance = msg.get("min_clearance")
            if isinstance(clearance, (int, float)):
                self.min_clearance = min(self.min_clearance, float(clearance))
