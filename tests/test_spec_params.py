"""Params with declared choices: the loader reads both forms, a campaign spreads the choices of the params
it was given no values for, and a value outside its param's choices is a clear input error (spec check,
proxy, fuzz)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignConfig, param_grid
from astaa_deft.orchestration.journal.journal import Journal
from astaa_deft.model.errors import InputError
from astaa_deft.engine.spec.params import check_param_values
from astaa_deft.engine.spec.loader import load_spec, load_spec_text

BODY = """
modules:
  - {name: a, command: ["{python}", "-c", "print('{prediction} {scenario} {seed}')"]}
  - {name: b, command: ["{python}", "-c", "pass"]}
channels:
  - {name: c, key: k, producer: a, consumers: [b], type: T}
types:
  T: {x: float64}
"""
PARAMS = """name: choices
params:
  seed: 7
  scenario: "a"
  prediction: {default: oracle, choices: [oracle, cv]}
"""


def spec_file(tmp_path: Path, params: str = PARAMS) -> Path:
    path = tmp_path / "sut.yaml"
    path.write_text(params + BODY)
    return path


def test_both_forms_load_and_a_default_defaults_to_the_first_choice():
    spec = load_spec_text(PARAMS + BODY)
    assert dict(spec.params) == {"seed": "7", "scenario": "a", "prediction": "oracle"}
    assert dict(spec.param_choices) == {"prediction": ("oracle", "cv")}
    first = load_spec_text("name: n\nparams:\n  speed: {choices: [fast, 2.5]}\n"
                           + BODY.replace("{prediction} {scenario} {seed}", "{speed}"))
    assert dict(first.params) == {"speed": "fast"} and first.param_choices["speed"] == ("fast", "2.5")


@pytest.mark.parametrize("declaration, line, message", [
    ("{default: ml, choices: [oracle, cv]}", 5, "default 'ml' is not one of its choices (oracle, cv)"),
    ("{default: oracle, choices: []}", 5, "'choices' must be a non-empty list of values"),
    ("{default: oracle}", 5, "lacks 'choices'"),
    ("{default: oracle, choices: [oracle, cv], help: x}", 5, "unknown key 'help'"),
    ("{choices: [cv, cv]}", 5, "choice 'cv' is listed twice"),
    ("[oracle, cv]", 5, "must be a scalar or {default: …, choices: […]}"),
])
def test_a_bad_declaration_is_named_with_its_line(declaration, line, message):
    with pytest.raises(InputError) as caught:
        load_spec_text(PARAMS.replace("{default: oracle, choices: [oracle, cv]}", declaration) + BODY, "sut.yaml")
    [problem] = caught.value.problems
    assert message in problem.message and problem.line == line and problem.file == "sut.yaml"


def test_a_value_outside_the_choices_is_refused_with_them():
    spec = load_spec_text(PARAMS + BODY)
    check_param_values(spec, {"prediction": ["cv"], "scenario": ["anything"]}, "--param")  # no choices: any value
    with pytest.raises(InputError) as caught:
        check_param_values(spec, {"prediction": ["cv", "ml"]}, "--param")
    [problem] = caught.value.problems
    assert problem.file == "--param" and "'prediction' is 'ml'" in problem.message
    assert problem.fix == "use one of: oracle, cv"


def test_a_campaign_spreads_declared_choices_unless_given_values(tmp_path):
    spec = load_spec(spec_file(tmp_path))
    assert param_grid({"scenario": ["a", "b"]}, spec) == [
        {"prediction": "oracle", "scenario": "a"}, {"prediction": "oracle", "scenario": "b"},
        {"prediction": "cv", "scenario": "a"}, {"prediction": "cv", "scenario": "b"}]
    assert param_grid({"prediction": ["cv"]}, spec) == [{"prediction": "cv"}]  # given values win
    assert param_grid({}, spec) == [{"prediction": "oracle"}, {"prediction": "cv"}]
    assert param_grid({"scenario": ["a"]}) == [{"scenario": "a"}]  # without a spec: only what was given
    with pytest.raises(InputError, match="'prediction' is 'ml'"):
        param_grid({"prediction": ["ml"]}, spec)
    # The campaign itself (its spec loaded, a real journal): the grid it cycles its cases through.
    campaign = Campaign(CampaignConfig(spec_path=spec_file(tmp_path), out=tmp_path / "out", cases=1),
                        Journal(tmp_path / "out"))
    assert {g["prediction"] for g in campaign.grid} == {"oracle", "cv"}


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "astaa_deft.cli", *args], capture_output=True, text=True,
                          timeout=120)


def test_spec_check_validates_a_param_against_its_choices(tmp_path):
    path = spec_file(tmp_path)
    ok = cli("spec", "check", str(path), "--param", "prediction=cv", "--param", "scenario=z")
    assert ok.returncode == 0, ok.stderr
    assert "params: prediction one of oracle/cv" in ok.stdout
    bad = cli("spec", "check", str(path), "--param", "prediction=ml")
    assert bad.returncode == 2 and "Traceback" not in bad.stderr
    assert "'prediction' is 'ml'" in bad.stderr and "use one of: oracle, cv" in bad.stderr
    proxy = cli("proxy", "--spec", str(path), "--param", "prediction=ml", "--duration", "1")
    assert proxy.returncode == 2 and "use one of: oracle, cv" in proxy.stderr and "Traceback" not in proxy.stderr
