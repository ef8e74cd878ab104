"""One base class for the tool's errors, and the CLI catching it once."""

from __future__ import annotations

import importlib
import pkgutil

import astaa_deft
from astaa_deft import cli
from astaa_deft.model.errors import AstaaDeftError


def _tool_modules():
    for info in pkgutil.walk_packages(astaa_deft.__path__, prefix="astaa_deft."):
        # The bundled driving stack is the system under test, not the tool: its errors are its own.
        if info.name.startswith("astaa_deft.demo"):
            continue
        yield importlib.import_module(info.name)


def test_every_exception_class_of_the_tool_derives_from_the_base():
    classes = {value for module in _tool_modules() for value in vars(module).values()
               if isinstance(value, type) and issubclass(value, BaseException)
               and value.__module__ == module.__name__}
    assert len(classes) >= 15  # the walk found the package's exception classes
    strays = sorted(c.__qualname__ for c in classes if not issubclass(c, AstaaDeftError))
    assert strays == []


def test_cli_prints_user_errors_once_and_exits_with_their_code(tmp_path, capsys):
    spec = tmp_path / "sut.yaml"
    spec.write_text("name: [unclosed\n")
    assert cli.main(["spec", "check", str(spec)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err and all(line.startswith(f"astaa-deft: error: {spec}") for line in err)


def test_a_huge_value_quoted_in_a_message_is_shortened_and_says_how_long():
    """Found by the generated bad input: a 5,000-digit type name made a 5 KB error line."""
    from astaa_deft.model.errors import Problem

    line = str(Problem("sut.yaml", 3, 4, f"unknown type '{'9' * 5000}' — did you mean 'bool'?", "fix the name"))
    assert len(line) < 300
    assert "(5002 characters)" in line and line.startswith("sut.yaml:3:4: unknown type '999")
    assert line.endswith("did you mean 'bool'? — fix the name")
    path = "/tmp/" + "d" * 150 + "/spec.yaml"  # a long path is still named in full
    assert path in str(Problem("x", None, None, f"see {path}"))
