"""Held faults: the mutations one policy made on consecutive messages of a channel are one item.

A policy that holds a value (every message of a window, the next N
messages) is one fault, and its messages act together: a planner that
bridges one or two bad inputs and fails on the third needs the hold, not one
of its messages. Minimising over single messages breaks the hold — ddmin
keeps the 1st and 3rd, or a single message that fails an open-loop replay
but not the closed loop — so the mutations stage works on *runs*: the
mutations of one policy (stacked policies alike) on one channel, to the same
consumers, on consecutive real messages. A run is then shortened as a whole
(:func:`.ddmin.shorten`: cut at its ends, never inside), and its field
changes are kept or reverted together. Pure logic.
"""

from __future__ import annotations

from collections.abc import Sequence

from astaa_deft.analysis.minimise.mutations import Mutation

Run = tuple[int, ...]
"""A held run: mutation numbers in message order (one number: a single mutation)."""


def held_runs(mutations: Sequence[Mutation]) -> list[Run]:
    """The mutations grouped into runs (each a policy's mutations on consecutive messages of one channel, to the
    same consumers), in the order of each run's first mutation."""
    open_runs: dict[tuple[str, str, tuple[str, ...], bool], list[Mutation]] = {}
    runs: list[list[Mutation]] = []
    for m in sorted(mutations, key=lambda m: m.number):
        key = (m.policy, m.channel, m.consumers, m.extra)
        current = open_runs.get(key)
        if current is not None and m.message_index == current[-1].message_index + 1:
            current.append(m)
            continue
        current = [m]
        open_runs[key] = current
        runs.append(current)
    return [tuple(m.number for m in run) for run in runs]


def flatten(runs: Sequence[Run]) -> list[int]:
    """The mutation numbers of these runs, in number order."""
    return sorted(n for run in runs for n in run)


def same_fields(run: Run, by_number: dict[int, Mutation]) -> bool:
    """Whether every mutation of the run changed the same field paths (its field changes can then be kept or
    reverted together, by index)."""
    paths = {tuple(c.path for c in by_number[n].fields) for n in run}
    return len(paths) == 1
