"""Liveliness tokens and queries cross the star per the spec's wiring (real subprocesses, real Zenoh)."""

from __future__ import annotations

from astaa_deft.engine.bus.topology import query_servers, token_destinations
from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.spec.loader import load_spec
from proxy_helpers import SUT_DIR, run_proxy

SERVICES_SPEC = SUT_DIR / "services.yaml"


def test_wiring_follows_channels_with_a_catch_all_for_undeclared_keys():
    spec = load_spec(SERVICES_SPEC)
    assert token_destinations(spec, "planner", "node/planner/alive") == ("simulator",)
    assert token_destinations(spec, "outsider", "node/planner/alive") == ()  # not its producer
    assert set(token_destinations(spec, "planner", "node/planner/extra")) == {"simulator", "client", "outsider"}
    assert query_servers(spec, "client", "svc/plan") == ("planner",)
    assert query_servers(spec, "outsider", "svc/plan") == ()
    assert set(query_servers(spec, "client", "svc/other")) == {"planner", "simulator", "outsider"}


def test_token_and_query_cross_the_star_only_where_wired(tmp_path):
    run_dir, log = tmp_path / "run", tmp_path / "run.mcap"
    res = run_proxy(SERVICES_SPEC, "--record", str(log), "--duration", "5", "--run-dir", str(run_dir))
    assert res.returncode == 0, res.stdout + res.stderr
    # The simulator waited on the planner's token and saw it (the declared one and the undeclared one).
    seen = (run_dir / "simulator.out").read_text().split()
    assert "node/planner/alive" in seen and "node/planner/extra" in seen
    # The client called the planner's queryable and got its answer, on the key it asked.
    assert (run_dir / "client.out").read_text().strip() == "reply svc/plan echo:route-7"
    # The outsider is wired to neither: no token, no reply.
    outsider = (run_dir / "outsider.out").read_text().splitlines()
    assert "token node/planner/alive" not in outsider and outsider[-1] == "noreply"
    # The undeclared token was reported once, as for undeclared publications.
    events = read_log(log).events("undeclared_key")
    assert [e["key"] for e in events] == ["liveliness:node/planner/extra"]
