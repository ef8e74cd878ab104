"""The baseline of a planner replay: the run replayed once with every mutation reverted.

Its outputs are what a test's frames give while they are the baseline's, and
its planner snapshots (every few frames, pickled) are where a test starts
replaying from; two planner states are the same when their pickles are, which
is how a test finds it is back in step with the baseline (:meth:`Baseline.converged`).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from astaa_deft.analysis.deft.baseline_walk import BaselineWalk
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
        planner = model.fresh_planner()
        try:  # a frame the unmutated replay fails on is judged by the tests that reach it: every frame kept
            self._walk = BaselineWalk(self.frames, planner, model.step, stride=max(1, len(self.frames) // SNAPSHOTS),
                                      pad=True)
        finally:
            planner.close()
        self.outputs: list[DecodedMessage | None] = self._walk.outputs
        self.error_frame: int | None = self._walk.error_frame
        self.error: str | None = (None if self.error_frame is None
                                  else f"output {self.error_frame}'s frame: {self._walk.error}")
        self.seconds = time.perf_counter() - started

    def restore(self, k: int) -> ReplayPlanner:
        """A planner in the baseline's state just before output ``k``'s frame."""
        s, state = self._walk.state(k)
        planner = self._model.fresh_planner()
        planner.restore(state)
        for i in range(s, k):  # only when snapshots are sparser than frames
            frame = self.frames[i]
            if frame is not None:
                self._model.step(planner, frame)
        return planner

    def converged(self, planner: ReplayPlanner, k: int) -> bool:
        """Is ``planner`` in the state the baseline was in before output ``k``'s frame?"""
        return planner.can_snapshot and self._walk.converged(planner, k)
