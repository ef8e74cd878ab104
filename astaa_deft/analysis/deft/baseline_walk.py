"""One replay of a module on its unmutated frames: the outputs, and its state every few frames.

Both the module-level search (:class:`~.module_search.ModuleBench`) and the
planner minimiser (:class:`~astaa_deft.analysis.minimise.replay_baseline.Baseline`)
start every replay from such a walk: restored from the snapshot just before
the first frame a fault changes, and back in step with the baseline once the
module's state pickles as the snapshot there does. They differ only in what a
frame that raises leaves behind, so that is passed in: ``pad`` (the minimiser
keeps every frame, the outputs past the error None: the tests that reach it
judge it) or not (the search judges no fault past it: the outputs end there,
and the caller cuts its frames to them).
"""

from __future__ import annotations

import copy
import pickle
from collections.abc import Callable, Sequence
from typing import Generic, TypeVar

from astaa_deft.analysis.deft.replay import ReplayPlanner
from astaa_deft.model.json import DecodedMessage

FrameT = TypeVar("FrameT")


class BaselineWalk(Generic[FrameT]):
    """``planner`` stepped through ``frames`` once (``step``), a snapshot every ``stride`` frames."""

    def __init__(self, frames: Sequence[FrameT | None], planner: ReplayPlanner,
                 step: Callable[[ReplayPlanner, FrameT], DecodedMessage | None], *, stride: int, pad: bool) -> None:
        self.snapshots: dict[int, object] = {}  # frame index → the state before it: pickled while states pickle
        self.pickled = True
        self.outputs: list[DecodedMessage | None] = []
        self.error_frame: int | None = None  # the frame whose step raised (StepHang included)
        self.error: str | None = None  # its exception, "TypeError: …"
        for k, frame in enumerate(frames):
            if k % stride == 0:
                self.snapshots[k] = self._snapshot(planner)
            if frame is None:
                self.outputs.append(None)
                continue
            try:
                self.outputs.append(step(planner, frame))
            except Exception as exc:  # the module's own error, whatever it is
                self.error_frame, self.error = k, f"{type(exc).__name__}: {exc}"
                if pad:
                    self.outputs.extend([None] * (len(frames) - k - 1))
                break

    def _snapshot(self, planner: ReplayPlanner) -> object:
        state = planner.snapshot()
        if self.pickled:
            try:
                return pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)
            except Exception:  # not picklable: deep copies from now on, and no convergence check
                self.pickled = False
                self.snapshots = {k: pickle.loads(v) for k, v in self.snapshots.items()}  # type: ignore[arg-type]
        return state

    def state(self, k: int) -> tuple[int, object]:
        """(s, a fresh copy of the state before frame s): the last snapshot at or before frame ``k``."""
        s = max(i for i in self.snapshots if i <= k)
        state = self.snapshots[s]
        return s, pickle.loads(state) if self.pickled else copy.deepcopy(state)  # type: ignore[arg-type]

    def converged(self, planner: ReplayPlanner, k: int) -> bool:
        """Is ``planner`` in the state the walk was in before frame ``k`` (known only where states pickle)?"""
        if not self.pickled or k not in self.snapshots:
            return False
        try:
            return pickle.dumps(planner.snapshot(), protocol=pickle.HIGHEST_PROTOCOL) == self.snapshots[k]
        except Exception:
            return False


__all__ = ["BaselineWalk"]
