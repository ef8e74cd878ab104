"""What a module that can run alone is: its records live in the model (``model/replay_module.py``).

Re-exported here for the spec's readers (``planner.py``, ``replay_section.py``)
and the code that names them by this module.
"""

from __future__ import annotations

from astaa_deft.model.replay_module import (
    EXCEPTIONS, FRAME_MODES, PER_OUTPUT, PER_TRIGGER, CollisionOracle, FrameMode, ReplayModule, SpecWord,
    StepExceptions, TrajectoryLayout,
)

__all__ = ["EXCEPTIONS", "FRAME_MODES", "PER_OUTPUT", "PER_TRIGGER", "CollisionOracle", "FrameMode", "ReplayModule",
           "SpecWord", "StepExceptions", "TrajectoryLayout"]
