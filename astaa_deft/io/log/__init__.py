"""MCAP test logs: what the recorder writes and every later stage reads."""
