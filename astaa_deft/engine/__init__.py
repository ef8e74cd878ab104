"""Tier 3, a run on the bus.

The spec read into the engine's parts, the Zenoh bus and its proxy,
interception, monitors, and the session that runs them together.

Inside the tier: ``session`` > ``spec`` > ``bus`` | ``intercept`` | ``monitor``.
Imports the io and model tiers.
"""
