"""One run of the SUT, orchestrated: the layer above bus/ (transport), log/ (file format) and monitor/ (evaluation).

:func:`run_session` is the library's single entry point for a run; commands,
minimisation, campaigns and benchmarks call it.
"""

from .bus_run import BusRun
from .loop import run_session
from .options import RunOptions, RunResult

__all__ = ["BusRun", "RunOptions", "RunResult", "run_session"]
