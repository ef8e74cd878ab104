"""A warm-started controller, rebuilt from the description of a stranger's MPC stack (for DeFT tests).

Every answer depends on all earlier ones (the previous solution is the warm
start), and its first cycles run before the first message of its slow input
(a 1 Hz path) has arrived: the factory contract passes an absent input by
leaving it out of the frame. Its output names the inputs it used (``used``:
their header.seq, null for an absent one) — the provenance a spec may declare.
"""

from __future__ import annotations

import os
from typing import Any


class WarmMpc:
    def __init__(self) -> None:
        self.u = 0.0  # the previous solution: the warm start of the next
        self.k = 0

    def step(self, frame: dict[str, Any]) -> dict[str, Any]:
        state, path = frame["state"], frame.get("path")  # path absent until its first message
        target = path["y"] if path is not None else 0.0
        self.k += 1
        for _ in range(3):  # a few warm-started iterations: each answer carries every earlier one
            self.u = 0.6 * self.u + 0.25 * (target - state["y"]) + 1e-3 * state["v"] / self.k
        return {"header": {"seq": self.k, "stamp": state["header"]["stamp"]}, "u": self.u,
                "used": {"state": state["header"]["seq"],
                         "path": path["header"]["seq"] if path is not None else None}}


class NoisyAfterForkMpc(WarmMpc):
    """The same controller, a little off (1e-15 relative) in any process forked after it was made — like a
    native solver whose thread pool restarts after a fork: not bit-stable across forked copies."""

    def __init__(self) -> None:
        super().__init__()
        self.pid = os.getpid()

    def step(self, frame: dict[str, Any]) -> dict[str, Any]:
        out = super().step(frame)
        if os.getpid() != self.pid:
            self.u += 1e-15 * (1.0 + abs(self.u))
            out["u"] = self.u
        return out


class NoisyAfterCopyMpc(WarmMpc):
    """The same controller, a little off (1e-15 relative) once its state was deep-copied or unpickled — like
    an extension object whose state round-trips through a narrower type."""

    def __init__(self) -> None:
        super().__init__()
        self.copied = False

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self.copied = True

    def step(self, frame: dict[str, Any]) -> dict[str, Any]:
        out = super().step(frame)
        if self.copied:
            self.u += 1e-15 * (1.0 + abs(self.u))
            out["u"] = self.u
        return out
