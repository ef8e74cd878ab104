"""Two cases at once never hear each other: each has its own router port, run dir and log."""

from __future__ import annotations

from pathlib import Path

from astaa_deft.orchestration.campaign.executors import LocalPool
from astaa_deft.orchestration.journal.model import BASELINE, PlannedCase
from astaa_deft.orchestration.campaign.payload import case_json

ECHO = Path(__file__).parent / "sut" / "echo.yaml"


def test_two_concurrent_cases_never_hear_each_other(tmp_path: Path):
    # Both talkers publish on the same key 'test/data'; on a shared bus each listener would get both streams.
    pool = LocalPool(2)
    counts = {"a": "30", "b": "70"}
    try:
        for name, count in counts.items():
            case = PlannedCase(case_id=name, kind=BASELINE, number=1, seed=0, params={"count": count, "rate": "100"},
                               testcase=None)
            pool.submit(name, {"spec": str(ECHO), "case": case_json(case), "run_dir": str(tmp_path / name),
                               "horizon": 3.0, "dictionaries": []})
        outcomes = {}
        while pool.pending():
            outcomes.update(dict(pool.done(timeout=1.0)))
    finally:
        pool.close()
    for name, count in counts.items():
        assert outcomes[name].status == "done", outcomes[name]
        heard = (tmp_path / name / "modules" / "listener.out").read_text().splitlines()
        assert len(heard) == int(count), f"case {name} heard {len(heard)} messages, its talker sent {count}"
        assert Path(outcomes[name].log_path).is_file()
    a_cfg = (tmp_path / "a" / "modules" / "zenoh-listener.json5").read_text()
    b_cfg = (tmp_path / "b" / "modules" / "zenoh-listener.json5").read_text()
    assert a_cfg != b_cfg  # different router ports


def test_an_anchored_case_mutates_once_then_ends_settle_seconds_later(tmp_path: Path):
    # The window counts from the first 'data' message (whenever the talker gets going), so the one
    # mutation always lands; then the run ends --settle seconds later, not at its 30 s horizon.
    from astaa_deft.orchestration.campaign.runner import CaseLimits, run_case
    from astaa_deft.engine.intercept.dictionary import load_dictionary
    from astaa_deft.engine.intercept.testcase import parse_testcase
    from astaa_deft.engine.spec.loader import load_spec

    spec, dictionary = load_spec(ECHO), load_dictionary()
    xml = (b'<testcase id="t" seed="1"><description>x</description><policy id="p1"><channel>data</channel>'
           b'<window from="0.3" to="30"><after channel="data" message="1"/></window><select limit="1"/>'
           b'<set><field path="value" value="dict:float.nan"/></set></policy></testcase>')
    testcase = parse_testcase(xml, "t", spec, dictionary)
    outcome = run_case(spec, testcase, {"count": "100000", "rate": "50"}, tmp_path / "case",
                       limits=CaseLimits(horizon=30.0, settle=1.0), dictionary=dictionary)
    assert outcome.status == "done", outcome
    assert outcome.reason == "settled"  # ended by the settle rule, not the 30 s horizon
    assert outcome.mutations == 1
