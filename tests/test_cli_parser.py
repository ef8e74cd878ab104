"""The command line assembled from the command modules: each declares its parser and runs its command."""

from __future__ import annotations

import subprocess
import sys

import pytest

from astaa_deft import cli

# argv that parses for each command (nothing is run: only the parser is asked), and the module that runs it.
COMMANDS = [
    (["spec", "check", "sut.yaml"], "spec_check"),
    (["spec", "discover", "--connect", "tcp/127.0.0.1:7447", "-o", "s.yaml"], "discover"),
    (["proxy", "--spec", "sut.yaml"], "proxy"),
    (["generate", "--spec", "sut.yaml", "--count", "1", "--seed", "0", "-o", "d"], "generate"),
    (["policy", "check", "case.xml"], "policy_check"),
    (["check", "run.mcap"], "check"),
    (["log", "info", "run.mcap"], "log_info"),
    (["extract", "run.mcap", "--spec", "sut.yaml", "-o", "d"], "extract"),
    (["minimise", "run.mcap", "-o", "d"], "minimise"),
    (["minimize", "run.mcap", "-o", "d"], "minimise"),
    (["demo"], "demo"),
    (["demo", "run"], "demo"),
    (["examples", "d"], "examples"),
]


@pytest.mark.parametrize("argv,module", COMMANDS, ids=[" ".join(a[:2]) for a, _ in COMMANDS])
def test_each_command_is_run_by_its_own_module(argv, module):
    args = cli.build_parser().parse_args(argv)
    assert args.func.__module__ == f"astaa_deft.cli.commands.{module}"


def test_every_command_of_the_help_is_declared():
    parser = cli.build_parser()
    top_help = parser.format_help()
    for command in ("spec", "proxy", "generate", "policy", "check", "log", "extract", "minimise", "fuzz", "report",
                    "demo", "examples"):
        assert f"\n    {command} " in top_help, command


def test_parsing_the_command_line_loads_no_zenoh_session_or_analysis():
    """`--help` and usage errors stay quick: commands import the library when they run (docs/performance.md)."""
    code = ("import sys; from astaa_deft import cli; cli.build_parser().parse_args(['spec', 'check', 'x.yaml']); "
            "print(sorted(m for m in ('zenoh', 'astaa_deft.engine.session.bus_run', 'astaa_deft.engine.monitor', "
            "'astaa_deft.analysis.minimise.workflow') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == "[]"
