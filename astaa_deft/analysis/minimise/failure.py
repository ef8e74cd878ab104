"""The failure a minimisation keeps: which invariant broke, where and when in the original run."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, kw_only=True)
class Failure:
    """The failure being minimised, as the log reported it."""

    invariant: str  # an invariant's name, or "(module exit)" for a crash no invariant named
    kind: str
    module: str | None
    channel: str | None
    at: float  # seconds since the run's start
    detail: str
    crash: str

    def describe(self) -> str:
        where = f" on '{self.channel}'" if self.channel else f" (module '{self.module}')" if self.module else ""
        return f"{self.invariant} ({self.kind}){where} at +{self.at:.2f} s: {self.detail}"
