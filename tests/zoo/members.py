"""The zoo's catalogue: every value of every axis, two strangers' stacks among them.

``MEMBERS`` is the whole zoo (the benchmark, ``-m slow``); ``SHORT`` a few
members with a couple of seconds of bus time each (the default test run).
"""

from __future__ import annotations

from dataclasses import replace

from zoo.member import Member

# A stranger's warm-started MPC controller (CasADi/IPOPT, 15 Hz), rebuilt from its description: it answers the
# newest trigger when a solve ends, dropping those that came meanwhile; its step keeps the previous solution as
# a warm start (every output depends on all earlier ones); its first outputs were computed before the first
# message of its 1 Hz path channel (c) arrived; forked copies are bit-identical.
MPC = Member("mpc", trigger="newest_idle", readiness="absent_first", reading="latched", state="warm",
             outputs="one", numerics="stable", cost_ms=(10.0, 45.0), rate_hz=15.0, c_hz=1.0, c_start_s=0.45,
             seconds=5.0, note="a stranger's warm-started MPC controller (15 Hz, newest trigger when a solve ends)")
# A stranger's native planner: 0.5-1.2 s a cycle, the newest message of each input read when a cycle starts (not
# when its trigger arrives), its state carried from cycle to cycle, not bit-stable after a fork (1e-15).
SLOW_PLANNER = Member("slow_planner", trigger="newest_idle", readiness="ready", reading="cycle_start",
                      state="warm", outputs="one", numerics="noisy_fork", cost_ms=(500.0, 1200.0), rate_hz=10.0,
                      seconds=9.0, note="a stranger's slow native planner (0.5-1.2 s, newest at cycle start)")

MEMBERS: tuple[Member, ...] = (
    MPC,
    SLOW_PLANNER,
    # every message of a: cheap steps, queued, none dropped
    Member("each_latched", trigger="each", reading="latched"),
    Member("each_warm", trigger="each", state="warm"),
    Member("each_counters_absent", trigger="each", readiness="absent_first", state="counters"),
    Member("each_none_some", trigger="each", reading="cycle_start", state="warm", outputs="none_some"),
    Member("each_sync_late", trigger="each", readiness="late", reading="sync"),
    Member("each_slow1hz_noisy", trigger="each", readiness="slow_1hz", state="warm", numerics="noisy_fork"),
    Member("each_several", trigger="each", state="counters", outputs="several", cost_ms=(1.0, 2.0)),
    Member("each_mid_cost", trigger="each", state="warm", cost_ms=(15.0, 35.0)),
    # a timer (15 Hz) reading the newest messages
    Member("timer_cycle", trigger="timer", reading="cycle_start"),
    Member("timer_warm_absent", trigger="timer", readiness="absent_first", reading="cycle_start", state="warm"),
    Member("timer_counters_late", trigger="timer", readiness="late", reading="sync", state="counters"),
    Member("timer_several", trigger="timer", state="warm", outputs="several"),
    Member("timer_heavy_noisy", trigger="timer", reading="cycle_start", state="warm", numerics="noisy_fork",
           cost_ms=(200.0, 400.0), timer_hz=5.0, seconds=6.0),
    # the newest trigger when idle (the others replaced)
    Member("newest_latched", trigger="newest_idle", state="warm", cost_ms=(30.0, 90.0)),
    Member("newest_sync_late", trigger="newest_idle", readiness="late", reading="sync", cost_ms=(40.0, 100.0)),
    Member("newest_none_slow1hz", trigger="newest_idle", readiness="slow_1hz", reading="cycle_start",
           state="counters", outputs="none_some", cost_ms=(10.0, 30.0)),
    # the oldest of a bounded queue (arrivals into a full queue dropped)
    Member("oldest_latched", trigger="oldest_queued", state="warm", cost_ms=(40.0, 70.0)),
    Member("oldest_cycle_absent", trigger="oldest_queued", readiness="absent_first", reading="cycle_start",
           state="counters", cost_ms=(30.0, 60.0)),
    Member("oldest_several_late", trigger="oldest_queued", readiness="late", outputs="several", cost_ms=(5.0, 15.0)),
    Member("oldest_sync_noisy", trigger="oldest_queued", readiness="slow_1hz", reading="sync", state="warm",
           numerics="noisy_fork", cost_ms=(50.0, 120.0)),
    # a trigger arriving while busy is dropped
    Member("drop_latched", trigger="drop_busy", state="warm", cost_ms=(60.0, 120.0)),
    Member("drop_cycle_none", trigger="drop_busy", readiness="absent_first", reading="cycle_start",
           outputs="none_some", cost_ms=(20.0, 60.0)),
    Member("drop_several_slow1hz", trigger="drop_busy", readiness="slow_1hz", state="counters", outputs="several",
           cost_ms=(30.0, 80.0)),
    Member("drop_sync_noisy", trigger="drop_busy", readiness="late", reading="sync", state="warm",
           numerics="noisy_fork", cost_ms=(80.0, 200.0)),
)

# Beside the catalogue (not a frame behaviour): a node that adds header.frame_id to every output, a field its
# step does not return. A spec that does not ignore it reproduces nothing, whatever the frames; the extraction
# must say so and name the ignore: line to add.
NODE_FRAME_ID = Member("node_frame_id", trigger="each", frames="per_output", frame_id="base_link",
                       note="the node adds header.frame_id to every output; its step does not return it")

SHORT_SECONDS = 2.0


def by_name(name: str) -> Member:
    for member in MEMBERS:
        if member.name == name:
            return member
    raise KeyError(f"no zoo member '{name}' (members: {', '.join(m.name for m in MEMBERS)})")


def short(member: Member, seconds: float = SHORT_SECONDS) -> Member:
    """The member with a couple of seconds of bus time (the default test run's form)."""
    return replace(member, seconds=min(member.seconds, seconds))


# The default test run's zoo: a per-trigger module with a warm start, the MPC, a timer module publishing several
# messages a cycle (cheap steps: seconds each on a loaded machine).
SHORT: tuple[Member, ...] = tuple(short(by_name(name)) for name in ("each_warm", "mpc", "timer_several"))
