"""Argument types shared by the command modules: bounded numbers, time budgets, cluster addresses.

Each is an argparse ``type``: called with the option's text, it returns the
value or raises ``argparse.ArgumentTypeError`` (a usage error, exit 2) that
says the accepted range. Pure: no I/O, safe from any thread.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from astaa_deft.model.errors import InputError
from astaa_deft.model.limits import DAY_S, MAX_PROCESSES, MAX_WINDOW_S

if TYPE_CHECKING:
    # The type of `ArgumentParser.add_subparsers()`'s result, private in argparse.
    SubParsers = argparse._SubParsersAction[argparse.ArgumentParser]


@dataclass(frozen=True, kw_only=True)
class NumberRange:
    """An argparse ``type``: a finite int or float in [low, high] (``low`` excluded when ``above_low``).

    Called with the option's text, returns the number or raises
    ``argparse.ArgumentTypeError`` (a usage error, exit 2) saying the range.
    """

    kind: type[int] | type[float]
    low: int | float
    high: int | float
    unit: str = ""
    above_low: bool = False

    def __call__(self, text: str) -> int | float:
        try:
            value = self.kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"'{text}' is not {self._noun}") from None
        if not math.isfinite(value) or value > self.high or value < self.low or (self.above_low and value == self.low):
            raise argparse.ArgumentTypeError(f"'{text}' is out of range: give {self._noun} {self}")
        return value

    @property
    def _noun(self) -> str:
        return "a whole number" if self.kind is int else "a number"

    def __str__(self) -> str:
        unit = f" {self.unit}" if self.unit else ""
        low = f"> {self.low:g}" if self.above_low else f"≥ {self.low:g}"
        if self.kind is int:
            return f"from {self.low:,} to {self.high:,}{unit}"
        return f"{low} and ≤ {self.high:g}{unit}"


CASES = NumberRange(kind=int, low=1, high=1_000_000)
SEED = NumberRange(kind=int, low=0, high=2**64 - 1)  # the test case schema's seed range
CAMPAIGN_SEED = NumberRange(kind=int, low=0, high=2**63 - 1)  # kept in the journal's SQLite INTEGER column
PROCESSES = NumberRange(kind=int, low=1, high=MAX_PROCESSES)
RERUNS = NumberRange(kind=int, low=0, high=100)
REPEATS = NumberRange(kind=int, low=1, high=100)
DOMAIN_ID = NumberRange(kind=int, low=0, high=232)  # ROS 2's valid domain ids
LISTEN_SECONDS = NumberRange(kind=float, low=0, high=3600, unit="s", above_low=True)
WINDOW_SECONDS = NumberRange(kind=float, low=0, high=MAX_WINDOW_S, unit="s", above_low=True)
RUN_SECONDS = NumberRange(kind=float, low=0, high=7 * DAY_S, unit="s", above_low=True)
THRESHOLD_M = NumberRange(kind=float, low=0, high=1000, unit="m")
MAX_BUDGET_S = 30 * DAY_S


def bounded(parser: argparse.ArgumentParser, flag: str, bounds: NumberRange, *, help: str = "",
            default: float | None = None, metavar: str | None = None, required: bool = False) -> None:
    """``parser.add_argument`` for a number option; its range is checked and said in ``--help``.

    ``default``, ``metavar`` and ``required`` mean what they mean to ``add_argument`` (whose defaults they keep).
    """
    parser.add_argument(flag, type=bounds, help=f"{help} [{bounds}]".strip(), default=default, metavar=metavar,
                        required=required)


def budget(text: str) -> float:
    """A fuzz campaign's time budget in seconds, at most MAX_BUDGET_S (argparse ``type``)."""
    from astaa_deft.cli.commands.fuzz import parse_budget

    try:
        seconds = parse_budget(text)
    except InputError as exc:
        raise argparse.ArgumentTypeError("; ".join(f"{p.message} ({p.fix})" for p in exc.problems)) from None
    if not 0 < seconds <= MAX_BUDGET_S:
        raise argparse.ArgumentTypeError(f"'{text}' is out of range: give more than 0 s and at most "
                                         f"{MAX_BUDGET_S / DAY_S:g} days (e.g. 90s, 30m, 2h)")
    return seconds


def cluster(text: str) -> str:
    """``--cluster``: a scheduler address as given, or ``local:K`` with K in PROCESSES (argparse ``type``)."""
    kind, sep, count = text.partition(":")
    if sep and kind == "local":
        if count:
            PROCESSES(count)
    elif "://" not in text:
        raise argparse.ArgumentTypeError(f"'{text}' is neither local:K nor a scheduler address like tcp://HOST:8786")
    return text
