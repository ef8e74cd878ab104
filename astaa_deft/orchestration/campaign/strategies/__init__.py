"""How a campaign draws its next test case: one interface, one module per strategy.

Each strategy's module registers its class on ``STRATEGIES`` (a
``model.registry.Registry``, defined in ``base``); adding a strategy is
adding a module here, and ``fuzz --strategy`` offers it.
"""

from __future__ import annotations

from astaa_deft.orchestration.campaign.strategies.base import STRATEGIES, Proposal, Strategy
from astaa_deft.orchestration.campaign.strategies.guided import GuidedStrategy
from astaa_deft.orchestration.campaign.strategies.random import RandomStrategy

__all__ = ["Proposal", "Strategy", "STRATEGIES", "RandomStrategy", "GuidedStrategy"]
