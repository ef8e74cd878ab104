"""Bounds on numbers a user gives on the command line and the tool stores: one place, so that what a journal
or a state file holds is read back with the same bounds the command line applied when it was written."""

from __future__ import annotations

DAY_S = 86_400.0
MAX_WINDOW_S = DAY_S  # a run's horizon, a settle window (seconds)
MAX_PROCESSES = 256  # runs at once, workers, jobs
