"""How a campaign draws its next test case: one interface, one module per strategy."""

from __future__ import annotations

from astaa_deft.orchestration.campaign.strategies.base import Proposal, Strategy
from astaa_deft.orchestration.campaign.strategies.decictor import (
    DecictorRandomDeltaStrategy, DecictorRandomStrategy, DecictorStrategy,
)
from astaa_deft.orchestration.campaign.strategies.guided import GuidedStrategy
from astaa_deft.orchestration.campaign.strategies.random import RandomStrategy

STRATEGIES: dict[str, type[Strategy]] = {
    "random": RandomStrategy, "guided": GuidedStrategy, "decictor": DecictorStrategy,
    "decictor-random": DecictorRandomStrategy, "decictor-random-delta": DecictorRandomDeltaStrategy,
}

__all__ = ["Proposal", "Strategy", "STRATEGIES", "RandomStrategy", "GuidedStrategy"]
