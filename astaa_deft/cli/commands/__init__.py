"""One module per command: ``add_parser(subparsers)`` declares it, ``run(args) -> int`` runs it.

``run`` turns the parsed arguments into the library's typed options and calls
a typed function of the same module (``check_log``, ``extract``, ``minimise``
…) that does the printing and picks the exit code; tests and the demo call
those. Library modules that load the monitors, the session or the analyses are
imported inside the functions that use them, so `astaa-deft --help` and a
command load only what that command needs (docs/performance.md, "cli-spec").
"""
