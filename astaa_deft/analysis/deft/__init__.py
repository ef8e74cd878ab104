"""DeFT: reconstruct the planner's input frames from a passive record, replay
the planner alone, validate, and export deterministic module tests."""
