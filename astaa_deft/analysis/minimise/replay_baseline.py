"""The baseline of a planner replay: the run replayed once with every mutation reverted.

Its outputs are what a test's frames give while they are the baseline's, and
its planner snapshots (every few frames, pickled) are where a test starts
replaying from; two planner states are the same when their pickles are, which
is how a test finds it is back in step with the baseline (:meth:`Baseline.converged`).
"""

from __future__ import annotations

import copy
import pickle
import time
from typing import TYPE_CHECKING, Any

from astaa_deft.analysis.deft.replay import ReplayPlanner
from astaa_deft.model.json import DecodedMessage

if TYPE_CHECKING:
    from astaa_deft.analysis.minimise.replay_model import ReplayModel

SNAPSHOTS = 400  # planner snapshots kept along the baseline replay (at most)


class Baseline:
    """The baseline replay of a :class:`~.replay_model.ReplayModel`'s run (built once per process)."""

    def __init__(self, model: ReplayModel) -> None:
        """Replay ``model``'s run with every mutation reverted, once: the snapshots and outputs tests start from.

        Snapshots are pickled: restoring one is a ``pickle.loads``, and two
        planner states are the same when their pickles are (see :meth:`run`).
        A planner that cannot be pickled is deep-copied instead, without that check.
        """
        self._model = model
        started = time.perf_counter()
        self.frames = model.frames({})
        self.keys = [f.key if f else None for f in self.frames]
        stride = max(1, len(self.frames) // SNAPSHOTS)
        planner = model.fresh_planner()
        # frame index → planner state: its pickle while the states pickle (``_pickled``), else the state itself
        self.snapshots: dict[int, Any] = {}
        self._pickled = True
        self.outputs: list[DecodedMessage | None] = []
        self.error: str | None = None
        self.error_frame: int | None = None
        for k, frame in enumerate(self.frames):
            if k % stride == 0:
                self.snapshots[k] = self._snapshot(planner)
            if frame is None:
                self.outputs.append(None)
                continue
            try:
                self.outputs.append(model.step(planner, frame))
            except Exception as exc:  # judged by the tests that reach it
                self.error = f"output {k}'s frame: {type(exc).__name__}: {exc}"
                self.error_frame = k
                self.outputs.extend([None] * (len(self.frames) - k - 1))
                break
        planner.close()
        self.seconds = time.perf_counter() - started

    def _snapshot(self, planner: ReplayPlanner) -> Any:
        state = planner.snapshot()
        if self._pickled:
            try:
                return pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)
            except Exception:  # not picklable: deep copies, and no convergence check
                self._pickled = False
                self.snapshots = {k: pickle.loads(v) for k, v in self.snapshots.items()}
        return state

    def restore(self, k: int) -> ReplayPlanner:
        """A planner in the baseline's state just before output ``k``'s frame."""
        s = max(i for i in self.snapshots if i <= k)
        planner = self._model.fresh_planner()
        state = self.snapshots[s]
        planner.restore(pickle.loads(state) if self._pickled else copy.deepcopy(state))
        for i in range(s, k):  # only when snapshots are sparser than frames
            frame = self.frames[i]
            if frame is not None:
                self._model.step(planner, frame)
        return planner

    def converged(self, planner: ReplayPlanner, k: int) -> bool:
        """Is ``planner`` in the state the baseline was in before output ``k``'s frame?"""
        if not self._pickled or k not in self.snapshots or not planner.can_snapshot:
            return False
        try:
            return pickle.dumps(planner.snapshot(), protocol=pickle.HIGHEST_PROTOCOL) == self.snapshots[k]
        except Exception:
            return False
