"""The `astaa-deft` command run in the test's own process: its exit code and what it printed on stderr.

A traceback escaping ``main`` fails the calling test; argparse's own usage errors exit 2. Used where a test
runs a command many times (a process each would cost seconds) or needs to see inside it (a counting wrapper).
"""

from __future__ import annotations

import contextlib
import io

from astaa_deft.cli.program import main


def run_in_process(*args: str) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main(list(args))
        except SystemExit as exc:
            code = int(exc.code or 0)
    return code, err.getvalue()
