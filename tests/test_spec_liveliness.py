"""Liveliness tokens declared in the spec (`liveliness:`): wired to their consumers, never reported as
undeclared keys; a bad declaration is one located error. Live part: real subprocesses, real Zenoh."""

from __future__ import annotations

import pytest

from astaa_deft.engine.bus.topology import token_destinations
from astaa_deft.engine.spec.loader import load_spec, load_spec_text
from astaa_deft.io.log.reader import read_log
from astaa_deft.model.errors import InputError
from proxy_helpers import SUT_DIR, run_proxy

SERVICES = (SUT_DIR / "services.yaml").read_text()
DECLARED = SERVICES + "liveliness:\n  - {key: node/planner/extra, producer: planner}\n"


def test_a_declared_token_reaches_its_consumers_or_every_other_module():
    spec = load_spec_text(DECLARED + "  - {key: node/client/up, producer: client, consumers: [planner]}\n",
                          name="services.yaml", base_dir=SUT_DIR)
    assert set(token_destinations(spec, "planner", "node/planner/extra")) == {"simulator", "client", "outsider"}
    assert token_destinations(spec, "client", "node/client/up") == ("planner",)
    assert token_destinations(spec, "planner", "node/planner/alive") == ("simulator",)  # a channel's key, as before


@pytest.mark.parametrize("entry, words", [
    ("{key: a/b, producer: nobody}", "unknown module 'nobody'"),
    ("{key: 'a/*', producer: planner}", "not a concrete Zenoh key"),
    ("{key: a/b}", "lacks 'producer'"),
    ("{key: a/b, producer: planner, consumers: [nobody]}", "unknown module 'nobody'"),
    ("{key: a/b, producer: planner, holder: x}", "unknown key 'holder'"),
])
def test_a_bad_token_declaration_is_one_located_problem(entry, words):
    with pytest.raises(InputError) as caught:
        load_spec_text(SERVICES + f"liveliness:\n  - {entry}\n", name="services.yaml", base_dir=SUT_DIR)
    [problem] = caught.value.problems
    assert words in str(problem) and str(problem).startswith(f"services.yaml:{SERVICES.count(chr(10)) + 2}:"), \
        str(problem)


def test_a_declared_token_crosses_the_star_and_is_not_reported_as_undeclared(tmp_path):
    spec = tmp_path / "services.yaml"
    spec.write_text(DECLARED.replace("{spec_dir}", str(SUT_DIR)))
    run_dir, log = tmp_path / "run", tmp_path / "run.mcap"
    res = run_proxy(spec, "--record", str(log), "--duration", "4", "--run-dir", str(run_dir))
    assert res.returncode == 0, res.stdout + res.stderr
    assert "node/planner/extra" in (run_dir / "simulator.out").read_text().split()
    assert read_log(log).events("undeclared_key") == []
    assert "undeclared" not in res.stdout + res.stderr
    assert load_spec(spec).liveliness[0].key == "node/planner/extra"
