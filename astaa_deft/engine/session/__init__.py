"""One run of the SUT, orchestrated: the layer above bus/ (transport), log/ (file format) and monitor/ (evaluation).

:func:`run_session` is the library's single entry point for a run; commands,
minimisation, campaigns and benchmarks call it.

The names below load on first use: the recorder process
(``python -m astaa_deft.engine.session.recorder``) lives in this package too, and
must not pay for the monitors and the launcher at every run's start.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from astaa_deft.engine.session.bus_run import BusRun
    from astaa_deft.engine.session.loop import run_session
    from astaa_deft.engine.session.options import RunOptions, RunResult
    from astaa_deft.engine.session.view import RunView

__all__ = ["BusRun", "RunOptions", "RunResult", "RunView", "run_session"]

_HOMES = {"BusRun": ".bus_run", "run_session": ".loop", "RunOptions": ".options", "RunResult": ".options",
          "RunView": ".view"}


def __getattr__(name: str) -> Any:
    if name in _HOMES:
        return getattr(importlib.import_module(_HOMES[name], __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
