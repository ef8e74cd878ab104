"""One zoo member: a combination of module behaviours, described as a frozen record.

Each axis is a word (the values listed in AXES); the numbers a member needs
beyond the axes (rates, costs, how long it runs) have defaults that fit the
axis values and can be set per member. ``Member.factory_args()`` is what the
generated spec gives the replay factory (and the module's own process builds
its step from the same dict): the member's behaviour inside one step, while
triggering and reading — what the process does around its step — stay in the
process.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

# Every value of every axis (the catalogue covers each one; tests check it).
AXES: dict[str, tuple[str, ...]] = {
    # What starts a cycle: each message of the trigger channel (queued, none dropped); a timer (ticks missed
    # while busy are skipped); the newest trigger when the module is idle (triggers meanwhile replaced);
    # the oldest of a bounded queue (arrivals into a full queue dropped); one arriving while busy dropped.
    "trigger": ("each", "timer", "newest_idle", "oldest_queued", "drop_busy"),
    # The third input 'c': present from the start; absent until its first message (after the module's
    # first outputs); arriving late (published `late_ms` after its stamp); at 1 Hz.
    "readiness": ("ready", "absent_first", "late", "slow_1hz"),
    # Which messages a cycle uses: those newest when the trigger arrived (latched); those newest when the
    # cycle starts; for each other input the buffered message whose stamp is nearest the trigger's.
    "reading": ("latched", "cycle_start", "sync"),
    # What a step carries to the next: nothing; a warm start (each output depends on every earlier one);
    # counters (steps taken, published).
    "state": ("none", "warm", "counters"),
    # Outputs per cycle: one; several (`parts` messages, one per step call); none for some cycles.
    "outputs": ("one", "several", "none_some"),
    # Results bit-stable wherever the step runs; or off by an ulp (< 1e-15) in a forked process or in a
    # copied (deep-copied, unpickled) instance, the error carried in the warm state.
    "numerics": ("stable", "noisy_fork"),
}

# Seeded defects (not an axis: the zoo's members have none unless asked): 'crash_on_nan' — a step given a NaN
# in any input's values raises, which kills the module's process (its spec says `exceptions: crash`);
# 'nan_state' — a NaN (or inf) input goes into the step's state unchecked, and the next cycle raises on that
# state: the failing cycle's own inputs are clean, so only a replay that carries the state reaches it.
DEFECTS = ("none", "crash_on_nan", "nan_state")

INPUTS = ("a", "b", "c")  # 'a' is the trigger channel (a timer module names it as its spec trigger too)
OUTPUT = "out"


@dataclass(frozen=True)
class Member:
    """A module behaviour (see AXES) and the numbers around it."""

    name: str
    trigger: str = "each"
    readiness: str = "ready"
    reading: str = "latched"
    state: str = "none"
    outputs: str = "one"
    numerics: str = "stable"
    cost_ms: tuple[float, float] = (1.0, 3.0)  # CPU time of one step, from..to (jitter derived from the frame)
    rate_hz: float = 20.0  # channel a (the trigger); a timer module's own tick rate is `timer_hz`
    b_hz: float = 10.0
    c_hz: float | None = None  # None: by readiness (ready 5, absent_first 5, late 10, slow_1hz 1)
    c_start_s: float | None = None  # first c message after the producer starts (None: by readiness)
    late_ms: float = 120.0  # readiness 'late': c is published this long after its stamp
    timer_hz: float = 15.0
    queue_depth: int = 3  # trigger 'oldest_queued'
    parts: int = 3  # outputs 'several'
    silent_every: int = 4  # outputs 'none_some': cycles on a trigger seq ≡ 3 (mod this) publish nothing
    warm: float = 0.5  # state 'warm': x_k = warm·x_{k-1} + (1 − warm)·u_k
    seconds: float = 4.0  # bus time the producer runs (the recorded run)
    frames: str | None = None  # the spec's frames mode (None: per_trigger for 'each' with one output a cycle)
    note: str = ""  # what the member stands for (the two strangers' stacks say so)
    defect: str = "none"  # a seeded defect (DEFECTS), for campaigns that must find it
    # The module's process adds header.frame_id = this to every output it publishes, as a node stamps its
    # frame; the step (the replay factory) does not return it. "" : no such field.
    frame_id: str = ""

    def __post_init__(self) -> None:
        for axis, values in AXES.items():
            value = getattr(self, axis)
            if value not in values:
                raise ValueError(f"member {self.name}: {axis} '{value}' is not one of {', '.join(values)}")
        if not self.name.replace("_", "").isalnum():
            raise ValueError(f"member name '{self.name}': letters, digits and _ only")
        lo, hi = self.cost_ms
        if not 0 < lo <= hi:
            raise ValueError(f"member {self.name}: cost_ms {self.cost_ms} must be 0 < from <= to")
        if self.defect not in DEFECTS:
            raise ValueError(f"member {self.name}: defect '{self.defect}' is not one of {', '.join(DEFECTS)}")
        if self.frames not in (None, "per_trigger", "per_output"):
            raise ValueError(f"member {self.name}: frames '{self.frames}'")

    # -- derived ------------------------------------------------------------------------------

    @property
    def frames_mode(self) -> str:
        """The spec's `frames:`: one frame per trigger where every trigger gets one step and at most one
        output (each message, one output or none); otherwise per output (the candidate search)."""
        if self.frames is not None:
            return self.frames
        return "per_trigger" if self.trigger == "each" and self.outputs != "several" else "per_output"

    @property
    def c_rate(self) -> float:
        if self.c_hz is not None:
            return self.c_hz
        return {"ready": 5.0, "absent_first": 5.0, "late": 10.0, "slow_1hz": 1.0}[self.readiness]

    @property
    def c_start(self) -> float:
        """When c's first message is made (s after the producer starts): after the module's first outputs
        for 'absent_first'."""
        if self.c_start_s is not None:
            return self.c_start_s
        first_outputs = 3.5 / self.rate_hz + self.cost_ms[1] * 2e-3
        return {"absent_first": max(0.4, first_outputs)}.get(self.readiness, 0.021)

    @property
    def c_lag(self) -> float:
        return self.late_ms * 1e-3 if self.readiness == "late" else 0.0

    @property
    def hang_after(self) -> float:
        """The spec's hang_after: far above a step's cost on a loaded machine."""
        return max(2.0, 10.0 * self.cost_ms[1] * 1e-3)

    def factory_args(self) -> dict[str, str]:
        """The replay factory's args (strings, as a spec gives them); the process builds its step from them."""
        return {"state": self.state, "outputs": self.outputs, "numerics": self.numerics,
                "cost_ms": f"{self.cost_ms[0]:g}-{self.cost_ms[1]:g}", "parts": str(self.parts),
                "silent_every": str(self.silent_every), "warm": repr(self.warm), "trigger": INPUTS[0],
                "inputs": ",".join(INPUTS), "defect": self.defect}

    def describe(self) -> dict[str, Any]:
        """The member as JSON (written beside its stack: the process and producer read it)."""
        body = asdict(self)
        body.update(frames_mode=self.frames_mode, c_rate=self.c_rate, c_start=self.c_start, c_lag=self.c_lag)
        return body

    def axes(self) -> dict[str, str]:
        return {axis: getattr(self, axis) for axis in AXES}
