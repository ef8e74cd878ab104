"""Tier 2, files and wire formats: codecs, the MCAP log, YAML with positions, opening inputs and writing outputs.

Imports only the model tier.
"""
