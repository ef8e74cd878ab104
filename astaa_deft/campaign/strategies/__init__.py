"""How a campaign draws its next test case: one interface, one module per strategy."""

from __future__ import annotations

from .base import Proposal, Strategy
from .decictor import DecictorRandomDeltaStrategy, DecictorRandomStrategy, DecictorStrategy
from .guided import GuidedStrategy
from .random import RandomStrategy

STRATEGIES: dict[str, type[Strategy]] = {
    "random": RandomStrategy, "guided": GuidedStrategy, "decictor": DecictorStrategy,
    "decictor-random": DecictorRandomStrategy, "decictor-random-delta": DecictorRandomDeltaStrategy,
}

__all__ = ["Proposal", "Strategy", "STRATEGIES", "RandomStrategy", "GuidedStrategy"]
