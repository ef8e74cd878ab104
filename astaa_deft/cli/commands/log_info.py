"""`astaa-deft log info FILE`: what the log holds and whether it is intact.

Informational, so exit 0 even for a log that stops early or is damaged: the
"finished cleanly" line says which, and each problem is printed once (stderr).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from astaa_deft.cli.arguments import SubParsers


def add_parser(subparsers: SubParsers) -> None:
    """Declare `log info` under the `log` command's actions."""
    info = subparsers.add_parser("info", help="channels, counts, rates, events of a log",
                                 epilog="example:\n  astaa-deft log info astaa-deft-demo/intercepted.mcap")
    info.add_argument("file", type=Path, help="an MCAP test log (a truncated one is read as far as it goes)")
    info.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """The parsed `log info` arguments to :func:`show_log_info`."""
    return show_log_info(args.file)


def show_log_info(path: Path) -> int:
    """Print what the log at ``path`` holds, its warnings on stderr: 0. InputError when it is no log at all."""
    from astaa_deft.engine.session.summary import format_info
    from astaa_deft.io.log.reader import read_log

    log = read_log(path)
    print(format_info(log, with_warnings=False))
    for w in log.warnings:
        print(f"warning: {w}", file=sys.stderr)
    return 0
