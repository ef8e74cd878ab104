"""How asynchronous, multi-rate channels become one sampled signal vector.

The rule (also in docs/monitors.md):

* every signal is **zero-order held**: it keeps the value of the latest
  message of its channel that gave a usable value (a finite number, or a
  boolean); messages that give none (field missing, NaN, undecodable) are
  skipped, so the signal keeps its previous value;
* the held values are read on a **fixed grid**: t_k = start + k * period,
  start being the run's start, for k = 0, 1, 2, ...;
* the sample at t_k sees every message with a time **at or before** t_k;
* sampling begins at the first grid point at which every signal has a
  value; earlier grid points are skipped, not guessed;
* a grid point is read when the first message *after* it arrives (or at the
  end of the run), so only message times decide which value a sample sees:
  online and offline runs of the same messages give the same samples.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence


class GridSampler:
    def __init__(self, start_ns: int, period_ns: int, names: Sequence[str]):
        self.start_ns = start_ns
        self.period_ns = period_ns
        self.names = tuple(names)
        self.values: dict[str, float] = {}
        self._next_index = 0

    def hold(self, name: str, value: float) -> None:
        self.values[name] = value

    @property
    def complete(self) -> bool:
        return len(self.values) == len(self.names)

    def due(self, time_ns: int, inclusive: bool) -> Iterator[int]:
        """Grid times not read yet that lie before ``time_ns`` (or at it, if ``inclusive``)."""
        while True:
            grid_ns = self.start_ns + self._next_index * self.period_ns
            if grid_ns > time_ns or (grid_ns == time_ns and not inclusive):
                return
            self._next_index += 1
            yield grid_ns

    def sample(self) -> list[tuple[str, float]]:
        values = self.values
        return [(name, values[name]) for name in self.names]
