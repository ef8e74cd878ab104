"""Tier 1, the domain model: the types every other tier exchanges.

Errors, the SUT's description (channels, message types, modules), field
paths, geometry and the records of a run (mutations, process exits,
violations, verdicts). Pure data and pure logic: nothing here opens a file,
a socket or a process, and nothing here imports another tier.
"""
