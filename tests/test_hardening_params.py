"""Params a command is given are checked, not silently run, and big choices lists are cheap.

`fuzz --params` with an undeclared name, an empty or repeated value, or a grid past the documented cap is one
input error naming the fix, before any journal is written; `spec check` of a param with 100,000 choices is
refused at once (a cap, and a linear check under it). Real CLI, in process.
"""

from __future__ import annotations

import contextlib
import io
import textwrap
from pathlib import Path

import pytest

from astaa_deft.cli import main
from astaa_deft.engine.spec.params import MAX_GRID
from astaa_deft.engine.spec.params_section import MAX_CHOICES

SPEC = textwrap.dedent("""\
    name: tiny
    modules: [{name: a, command: "true"}, {name: b, command: "true"}]
    channels: [{name: data, key: t/data, producer: a, consumers: [b], type: Sample}]
    types:
      Sample: {seq: uint64, value: float64}
    params:
      scenario: {default: cut_in, choices: [cut_in, red_light]}
      defects: "off"
      speed: "10"
    """)


def run(*argv: str) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, err.getvalue()


@pytest.mark.parametrize("given, says", [
    (["nosuch=1"], "param 'nosuch' is not declared"),
    (["scenaro=cut_in"], "did you mean 'scenario'"),
    (["defects=on,on,on"], "'defects' lists 'on' more than once"),
    (["scenario=,"], "gives 'scenario' no value"),
    (["scenario=cut_in,,red_light"], "has an empty value"),
    (["defects=on", "defects=off"], "param 'defects' is given twice"),
    (["scenario=nowhere"], "not one of the choices"),
    ([f"speed={','.join(str(v) for v in range(10_000))}"], f"more than {MAX_GRID:,} combinations"),
    ([f"speed={','.join(str(v) for v in range(40))}", f"defects={','.join(str(v) for v in range(40))}"],
     "40 (speed) × 40 (defects)"),
])
def test_bad_fuzz_params_are_one_input_error_and_leave_no_journal(given, says, tmp_path):
    spec = tmp_path / "spec.yaml"
    spec.write_text(SPEC)
    out = tmp_path / "campaign"
    code, err = run("fuzz", "--spec", str(spec), "-o", str(out), "--params", *given, "--cases", "1",
                    "--baseline", "1", "--no-minimise", "--horizon", "2")
    assert code == 2, err
    assert says in err and "astaa-deft: error: --params:" in err and "Traceback" not in err
    assert not (out / "journal.sqlite").exists()  # fixed and run again: no "a campaign is already here"


def test_an_undeclared_param_for_proxy_and_spec_check_is_refused_too(tmp_path):
    spec = tmp_path / "spec.yaml"
    spec.write_text(SPEC)
    code, err = run("spec", "check", str(spec), "--param", "nosuch=1")
    assert code == 2 and "param 'nosuch' is not declared" in err and "declared: defects, scenario, speed" in err


def test_spec_check_of_100000_choices_is_refused_at_once(tmp_path):
    choices = ", ".join(f"s{i}" for i in range(100_000))
    spec = tmp_path / "spec.yaml"
    spec.write_text(SPEC.replace("choices: [cut_in, red_light]", f"choices: [{choices}]").replace(
        "default: cut_in, ", ""))
    code, err = run("spec", "check", str(spec))
    assert code == 2 and f"lists 100,000 choices (at most {MAX_CHOICES:,})" in err
    assert f"{spec}:7:" in err  # file, line, column of the list


def test_the_most_choices_allowed_load_and_a_repeat_among_them_is_named(tmp_path):
    choices = [f"s{i}" for i in range(MAX_CHOICES)]
    spec = tmp_path / "spec.yaml"
    declared = "{default: cut_in, choices: [cut_in, red_light]}"
    spec.write_text(SPEC.replace(declared, f"{{choices: [{', '.join(choices)}]}}"))
    assert run("spec", "check", str(spec))[0] == 0
    choices[-1] = "s7"
    spec.write_text(SPEC.replace(declared, f"{{choices: [{', '.join(choices)}]}}"))
    code, err = run("spec", "check", str(spec))
    assert code == 2 and "choice 's7' is listed twice" in err


def test_good_params_still_make_their_grid(tmp_path):
    from astaa_deft.engine.spec.loader import load_spec
    from astaa_deft.orchestration.campaign.campaign import param_grid

    spec = tmp_path / "spec.yaml"
    spec.write_text(SPEC)
    grid = param_grid({"defects": ["on", "off"]}, load_spec(spec))
    assert len(grid) == 4 and {"defects": "on", "scenario": "red_light"} in grid
    assert Path(spec).is_file()
