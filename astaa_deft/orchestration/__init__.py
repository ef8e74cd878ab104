"""Tier 5, many runs: fuzz campaigns (scheduling, executors, the journal, buckets, the report).

Imports the analysis tier and everything below it.
"""
