"""The command line teaches: each command's --help has a description, every option a help text that states its
default, an example epilog, and a mistyped option or command names the closest match."""

from __future__ import annotations

import argparse
import subprocess
import sys

import pytest

from astaa_deft import cli


def _commands(parser: argparse.ArgumentParser, path: tuple[str, ...] = ()):
    """Every (path, parser) of the command line, the top level included; an alias once."""
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            seen: set[int] = set()
            for name, sub in action.choices.items():
                if id(sub) not in seen:
                    seen.add(id(sub))
                    yield from _commands(sub, (*path, name))


COMMANDS = list(_commands(cli.build_parser()))


def test_the_walk_reaches_every_command():
    names = {" ".join(path) for path, _ in COMMANDS}
    assert {"fuzz", "demo", "demo run", "spec check", "spec discover", "verify", "export", "report", "log info",
            "policy check", "examples"} <= names


@pytest.mark.parametrize("path,parser", COMMANDS, ids=[" ".join(p) or "astaa-deft" for p, _ in COMMANDS])
def test_each_command_has_a_description_and_an_example(path, parser):
    assert parser.description and "\n" not in parser.description.strip()
    assert parser.epilog and "astaa-deft " in parser.epilog, "an example command line in the epilog"
    text = parser.format_help()
    assert parser.epilog.splitlines()[-1].strip() in text  # the epilog's lines are kept as written


@pytest.mark.parametrize("path,parser", COMMANDS, ids=[" ".join(p) or "astaa-deft" for p, _ in COMMANDS])
def test_each_option_has_help_that_states_its_default(path, parser):
    formatter = parser._get_formatter()
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._VersionAction, argparse._SubParsersAction)):
            continue
        name = "/".join(action.option_strings) or action.dest
        assert action.help, f"{' '.join(path)} {name}: no help"
        if action.option_strings and not action.required:
            shown = formatter._expand_help(action)
            assert "default" in shown.lower(), f"{' '.join(path)} {name}: default not stated: {shown}"


def _usage_error(argv: list[str]) -> str:
    out = subprocess.run([sys.executable, "-m", "astaa_deft.cli", *argv], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2, out
    return out.stderr


def test_a_mistyped_option_names_the_closest_one():
    assert "did you mean --budget?" in _usage_error(["fuzz", "--spec", "s.yaml", "-o", "c", "--budjet", "1m"])


def test_a_mistyped_option_before_a_value_is_not_read_as_an_action():
    err = _usage_error(["demo", "--scenaro", "cut_in"])
    assert "did you mean --scenario?" in err and "invalid choice" not in err


def test_a_mistyped_command_names_the_closest_one():
    assert "did you mean 'fuzz'?" in _usage_error(["fuz", "-o", "c"])


def test_a_known_option_abbreviated_still_parses():
    assert cli.build_parser().parse_args(["fuzz", "-o", "c", "--budg", "1m"]).budget == 60.0


def test_examples_copies_what_the_readme_names_and_keeps_what_is_there(tmp_path):
    from astaa_deft.demo.bundled import demo_policy_path, demo_spec_path

    out = tmp_path / "mine"
    subprocess.run([sys.executable, "-m", "astaa_deft.cli", "examples", str(out)], check=True, timeout=60,
                   capture_output=True, cwd=tmp_path)
    assert (out / "specs" / "demo_av.yaml").read_bytes() == demo_spec_path().read_bytes()
    assert (out / "policies" / "examples" / "demo_nan_speed_limit.xml").read_bytes() == demo_policy_path().read_bytes()
    assert (out / "dictionaries" / "default.yaml").is_file()
    (out / "specs" / "demo_av.yaml").write_text("mine")
    again = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "examples", str(out)], timeout=60,
                           capture_output=True, text=True, cwd=tmp_path)
    assert again.returncode == 0 and "kept" in again.stdout
    assert (out / "specs" / "demo_av.yaml").read_text() == "mine"
    checked = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "policy", "check",
                              "policies/examples/demo_nan_speed_limit.xml", "--spec", str(demo_spec_path())],
                             timeout=60, capture_output=True, text=True, cwd=out)
    assert checked.returncode == 0, checked.stderr
