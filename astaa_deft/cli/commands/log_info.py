"""`astaa-deft log info FILE`: what the log holds and whether it is intact.

Informational, so exit 0 even for a log that stops early or is damaged: the
"finished cleanly" line says which, and each problem is printed once (stderr).
"""

from __future__ import annotations

import sys
from pathlib import Path

from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.session.summary import format_info


def run(path: Path) -> int:
    log = read_log(path)
    print(format_info(log, with_warnings=False))
    for w in log.warnings:
        print(f"warning: {w}", file=sys.stderr)
    return 0
