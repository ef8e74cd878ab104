"""The `astaa-deft` command line: parse arguments, call one command module.

Exit codes: 0 ok, 1 a finding (a test failed, a module crashed), 2 usage or
input error (printed as one line per problem, never a traceback), 3 a run not
fully observed (verdict withheld), 4 the output cannot be written (read-only,
full, over the file size limit, a file in the way, no temporary directory:
``output_place.EXIT_CANNOT_WRITE``).

The parser is assembled in :mod:`astaa_deft.cli.program` from the command
modules in :mod:`astaa_deft.cli.commands`; ``astaa_deft.cli:main`` is the
console script, ``python -m astaa_deft.cli`` runs the same.
"""

from __future__ import annotations

from astaa_deft.cli.program import build_parser, main

__all__ = ["build_parser", "main"]
