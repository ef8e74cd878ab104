"""The runner and its shadow: cheap outputs stepped in the replay process, a copy following one output behind.

A wrong candidate hands the output over to the shadow, which holds the state
from before it (fork_replay.shadow); an expensive output's first candidate
is stepped here under a CPU limit, a checkpoint copy waiting.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar, cast

from astaa_deft.analysis.deft.fork_replay import Following, Shadow, cpu_limit, drop, hand_over, next_word, shadow, tell

StepOutcome = TypeVar("StepOutcome")  # what stepping one candidate gives (the search's outcome of it)

# The runner's word to its shadow on an output: (KEEP, i): candidate i is kept, step it and follow on;
# (TRY_ON, outcomes so far by candidate): carry on as the runner from the state before the output, trying
# the candidates not tried yet. Each word also carries the runner's counters.
KEEP, TRY_ON = "keep", "try on"
Word = tuple[str, object, tuple[int, int]]  # (kind, argument, the runner's counters: hits, misses)


def _word(received: object) -> Word:
    """A word as read off the pipe: a copy of this very process (the runner) wrote it with :meth:`tell`."""
    return cast(Word, received)


IN_TURN = 2  # a cheap output's candidates stepped in turn at most (then a forked search, with time limits)


@dataclass(kw_only=True)
class Speculation:
    """The runner's shadow (a copy one output behind, see fork_replay.shadow), or in a shadow what it follows."""

    shadow: Shadow | None = None  # in the runner
    following: Following | None = None  # in a shadow: where the runner's word comes from
    # The last output kept was reproduced field for field: then a candidate that reproduces only the
    # trajectory (a standing ego: the same points from another pose message, another stamp) does not end
    # the search, the others are searched for the exact one (none: the closest is kept as before). A stack
    # whose outputs never match exactly is not held up: after one such output this is off again.
    expect_exact: bool = False
    hits: int = 0  # cheap outputs whose first candidate was accepted
    misses: int = 0  # … was not: the shadow took over and tried the others

    def shadow_here(self) -> None:
        """Fork a shadow unless one follows already (in the new shadow this returns with ``following`` set)."""
        if self.shadow is None and self.following is None:
            handle = shadow()
            if isinstance(handle, Following):
                self.following = handle
            else:
                self.shadow = handle

    def word(self) -> tuple[str, object]:
        """In a shadow: the runner's word on the output at hand (it exits when the runner has none)."""
        assert self.following is not None
        kind, argument, (self.hits, self.misses) = _word(next_word(self.following))
        if kind != KEEP:  # from here on this process is the runner
            os.close(self.following.word_fd)
            self.following = None
        return kind, argument

    def tell(self, kind: str, argument: object) -> None:
        """In the runner: its word to the shadow; with any word but KEEP the runner ends here."""
        if self.shadow is None:
            assert kind == KEEP, "only a runner with a shadow hands an output over"
            return
        word: Word = (kind, argument, (self.hits, self.misses))
        if kind == KEEP:
            tell(self.shadow, word)
        else:
            hand_over(self.shadow, word)

    def let_go(self) -> None:
        if self.shadow is not None:
            drop(self.shadow)
            self.shadow = None


def step_in_turn(count: int, run: Callable[[int], StepOutcome], accepted: Callable[[StepOutcome], bool],
                 speculation: Speculation, *, in_turn: bool
                 ) -> tuple[tuple[int, StepOutcome] | None, dict[int, StepOutcome]]:
    """(candidate and outcome kept, or None; candidates tried in vain) for one output, stepped in this process.

    ``in_turn`` (a cheap output with several candidates): the first
    ``IN_TURN`` candidates are stepped here in order, a shadow holding the
    state from before the output; the first accepted is kept and the shadow
    steps it too; a wrong one hands the output over to the shadow, which
    tries the next (with a shadow of its own). A lone candidate is stepped
    here (the shadow, if any, follows). Anything else (None) is left to the
    forked search, whose time limits stop a wrong frame that searches long.
    """
    tried: dict[int, StepOutcome] = {}  # outcomes of the candidates tried so far on this output
    while True:
        if in_turn:
            speculation.shadow_here()  # (in the new shadow this returns too: it waits for the word on this output)
        if speculation.following is not None:
            kind, argument = speculation.word()
            if kind == TRY_ON:  # a candidate was wrong: this process, in the state from before, tries the next
                tried = cast(dict[int, StepOutcome], argument)  # the runner's own ``tried``
                if len(tried) >= IN_TURN:
                    return None, dict(tried)
                continue
            kept = cast(int, argument)  # KEEP: the index of the candidate the runner kept
            return (kept, run(kept)), {}
        if count == 1:
            outcome = run(0)
            if outcome is None:
                return None, {}
            speculation.tell(KEEP, 0)
            return (0, outcome), {}
        if not in_turn:
            return None, {}
        index = len(tried)  # in turn: the candidates in order
        outcome = run(index)
        if accepted(outcome):
            speculation.hits += index == 0
            speculation.tell(KEEP, index)
            return (index, outcome), {}
        speculation.misses += index == 0
        tried[index] = outcome
        speculation.tell(TRY_ON, tried)  # does not return: the shadow carries on from the state before


DONE = "done"  # the runner's word to an output's checkpoint copy: its first candidate was kept, exit
DIED = "died"  # what a checkpoint copy reads when its runner died on the first candidate (cut, or crashed)


def step_first_here(run: Callable[[int], StepOutcome | None], accepted: Callable[[StepOutcome | None], bool],
                    speculation: Speculation, limit_s: float
                    ) -> tuple[tuple[int, StepOutcome | None] | None, dict[int, StepOutcome | None]]:
    """(candidate and outcome kept, or None; candidates tried in vain) of an expensive output: its first
    candidate stepped right here, as a plain replay would — no fork to wait for — a checkpoint copy forked
    just before holding the state from before the output.

    Right (the usual case: the learned way first), the copy is told to exit.
    Wrong, the output goes over to the copy, which searches the others
    (forked, with their time limits) and this process ends. The step may
    use ``limit_s`` of CPU time: past it this process is killed (native code
    too) and the copy takes over as from a wrong candidate, retrying it
    last under the full limit if nothing else is accepted.
    """
    if speculation.following is not None:  # a shadow of cheap outputs: the runner drops it here, it exits
        speculation.word()
    speculation.let_go()  # a shadow following cheap outputs is not this output's checkpoint
    handle = shadow()
    if isinstance(handle, Following):  # the checkpoint copy, at the state from before the output
        word = _word(next_word(handle, at_end=(DIED, None, (speculation.hits, speculation.misses))))
        os.close(handle.word_fd)
        kind, argument, (speculation.hits, speculation.misses) = word
        if kind == DONE:
            os._exit(0)
        # Tried in vain (its outcome), or cut (None): the others first, then it again under the search's limits.
        return None, {0: cast(dict[int, StepOutcome], argument)[0] if kind == TRY_ON else None}
    with cpu_limit(limit_s):
        outcome = run(0)
    counters = (speculation.hits, speculation.misses)
    if accepted(outcome):
        tell(handle, (DONE, None, counters))
        drop(handle)
        return (0, outcome), {}
    hand_over(handle, (TRY_ON, {0: outcome}, counters))  # does not return: the copy carries on
    raise AssertionError("unreachable")
