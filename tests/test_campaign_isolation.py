"""Two cases at once never hear each other: each has its own router port, run dir and log."""

from __future__ import annotations

from pathlib import Path

from astaa_deft.campaign.executors import LocalPool
from astaa_deft.campaign.model import BASELINE, PlannedCase

ECHO = Path(__file__).parent / "sut" / "echo.yaml"


def test_two_concurrent_cases_never_hear_each_other(tmp_path: Path):
    # Both talkers publish on the same key 'test/data'; on a shared bus each listener would get both streams.
    pool = LocalPool(2)
    counts = {"a": "30", "b": "70"}
    try:
        for name, count in counts.items():
            case = PlannedCase(name, BASELINE, 1, 0, {"count": count, "rate": "100"}, None)
            pool.submit(name, {"spec": str(ECHO), "case": case.to_json(), "run_dir": str(tmp_path / name),
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
