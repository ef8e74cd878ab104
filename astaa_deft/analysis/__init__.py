"""Tier 4, what is derived from runs and logs.

DeFT's module tests, ROS 2 discovery, Decictor's search and delta-debugging
minimisation.

Inside the tier: ``minimise`` > ``decictor`` > ``deft`` | ``ros2``.
Imports the engine, io and model tiers.
"""
