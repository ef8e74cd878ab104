"""The `astaa-deft` program: its parser assembled from the command modules, and ``main``.

Each command module declares its own subparser (``add_parser``) and a thin
``run(args)``; this module only orders them under the top-level parser and
the action groups (`spec`, `policy`, `log`), and maps errors to exit codes.
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, cast

from astaa_deft import __version__
from astaa_deft.cli import campaign_commands
from astaa_deft.cli.commands.console import forget_stop, interrupted_exit_code, last_stop, stop_as_interrupt
from astaa_deft.cli.parser import Parser
from astaa_deft.cli.commands import (
    check,
    demo,
    discover,
    examples,
    export,
    extract,
    generate,
    log_info,
    minimise,
    policy_check,
    proxy,
    spec_check,
    verify,
)
from astaa_deft.io.output_place import ignore_file_size_signal
from astaa_deft.model.errors import AstaaDeftError

if TYPE_CHECKING:
    from astaa_deft.cli.arguments import SubParsers

EPILOG = """\
first steps:
  astaa-deft demo                       the whole pipeline on the bundled driving stack (about 2 min)
  astaa-deft examples my-first-specs    copy the bundled spec, test cases and dictionary to a folder
  astaa-deft COMMAND --help             each command's options, defaults and an example

exit codes: 0 ok, 1 a finding, 2 usage or input error, 3 a run not fully observed,
4 the output cannot be written, 130 interrupted (Ctrl-C), 143 terminated (SIGTERM)"""


def build_parser() -> argparse.ArgumentParser:
    """The whole command line: each command's ``func`` default is the ``run(args) -> int`` to call."""
    p = Parser(
        prog="astaa-deft",
        description="Test robot software on its own Zenoh bus: record, replay, intercept.",
        epilog=EPILOG,
    )
    p.add_argument("--version", action="version", version=f"astaa-deft {__version__}")
    # Typed as the command modules declare it: argparse builds every subparser with the parent's class (Parser).
    sub = cast("SubParsers", p.add_subparsers(dest="command", metavar="COMMAND"))
    sub.required = True

    spec = _actions(sub, "spec", "work with SUT specs")
    spec_check.add_parser(spec)
    discover.add_parser(spec)
    proxy.add_parser(sub)
    generate.add_parser(sub)
    policy_check.add_parser(_actions(sub, "policy", "work with ASTAA test cases"))
    check.add_parser(sub)
    log_info.add_parser(_actions(sub, "log", "inspect test logs"))
    extract.add_parser(sub)
    minimise.add_parser(sub)
    campaign_commands.add_fuzz_parser(sub)
    campaign_commands.add_report_parser(sub)
    verify.add_parser(sub)
    export.add_parser(sub)
    demo.add_parser(sub)
    examples.add_parser(sub)
    return p


def _actions(sub: SubParsers, command: str, help: str) -> SubParsers:
    """A command that only groups actions (`spec check`, `log info`): its subparsers, one required."""
    group = sub.add_parser(command, help=help, epilog=f"example:\n  astaa-deft {command} ACTION --help")
    actions = group.add_subparsers(dest=f"{command}_command", metavar="ACTION")
    actions.required = True
    return actions


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv`` (default: ``sys.argv[1:]``), run the command and return its exit code.

    Exit codes: 0 ok, 1 a finding, 2 usage or input error (one line per problem on stderr, no traceback),
    3 a run not fully observed, 4 the output cannot be written, 130 interrupted (Ctrl-C), 143 terminated
    (SIGTERM: it ends every command as Ctrl-C does). argparse's own usage errors
    and ``--help`` raise SystemExit as usual. An internal error (no exit code) propagates with its traceback.
    """
    args = build_parser().parse_args(argv)
    ignore_file_size_signal()  # past `ulimit -f` a write fails with EFBIG, reported, instead of killing the tool
    forget_stop()
    try:
        # SIGTERM ends every command as Ctrl-C does (its children stopped, what it wrote finished), not outright.
        with stop_as_interrupt():
            code: int = args.func(args)
        return interrupted_exit_code() if code == 130 else code
    except AstaaDeftError as exc:
        if exc.exit_code is None:  # an internal error escaping is a bug: keep its traceback
            raise
        for line in exc.user_lines():
            print(f"astaa-deft: error: {line}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print(f"astaa-deft: {'terminated' if last_stop() == 'SIGTERM' else 'interrupted'}", file=sys.stderr)
        return interrupted_exit_code()
