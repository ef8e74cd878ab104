"""`astaa-deft log info FILE`."""

from __future__ import annotations

import sys
from pathlib import Path

from ..log.reader import read_log
from ..log.summary import format_info


def run(path: Path) -> int:
    log = read_log(path)
    print(format_info(log))
    for w in log.warnings:
        print(f"warning: {w}", file=sys.stderr)
    return 0
