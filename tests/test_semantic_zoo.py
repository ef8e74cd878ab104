"""The semantic zoo live (tests/sut/semantic_zoo.yaml: real source and consumer processes, real Zenoh on
loopback, a real MCAP log): each semantic family's generated case, run directly, reaches that family's
seeded defect (the consumer's traceback names it); the same cases with the defects off leave the run clean.

Each family's case is the first of its probes in the campaign's semantic schedule that reaches the defect
through the real Interceptor (tests/zoo_helpers.py), so what runs live is what a campaign would propose.
"""

from __future__ import annotations

import random
from dataclasses import replace
from pathlib import Path

import pytest

from astaa_deft.engine.intercept import TestCase
from astaa_deft.engine.intercept import generate as gen
from proxy_helpers import run_proxy
from zoo_helpers import DICTIONARY, SEMANTIC, ZOO_SPEC, ZOO_SPEC_PATH, reached

SECONDS = "2.5"  # the source's scenario; every window opens in its first 1.2 s (counted from its first message)
# Each family's seeded defect in tests/sut/zoo_consumer.py: the consumer's check that raises it (the
# traceback's innermost frame) and what the exception line begins with (the type defect raises KeyError on a
# removed field, TypeError on a mistyped one).
RAISES = {"boundary": ("speed", ("IndexError",)), "angle": ("heading", ("ValueError: angle defect",)),
          "units": ("gap", ("ValueError: units defect",)), "arrays": ("path", ("ValueError: arrays defect",)),
          "type": ("battery", ("KeyError: 'battery'", "TypeError")),
          "siblings": ("lateral", ("ValueError: siblings defect",)), "stale": ("odometer", ("ZeroDivisionError",))}


def raised(consumer_log: str) -> tuple[str, str]:
    """The innermost frame's function and the exception line of the consumer's (last) traceback."""
    tail = consumer_log[consumer_log.rindex("Traceback"):].splitlines()
    frames = [line.rsplit(" in ", 1)[-1] for line in tail if line.startswith('  File "')]
    exception = next(line for line in reversed(tail) if line and not line.startswith(" "))
    return frames[-1], exception


def family_case(name: str) -> TestCase:
    """The first probe of ``name`` in the semantic schedule that reaches its defect (offline)."""
    targets = gen.FaultTargets.of(ZOO_SPEC, DICTIONARY)
    for number in range(400):
        found = gen.semantic_probe(targets, 1, number)
        assert found is not None
        probe, lap = found
        if probe.family != name:
            continue
        testcase = gen.probe_testcase(f"zoo-{name}", random.Random(number), probe, lap, duration=1.5, anchor="state")
        if reached(testcase, defects=True) == name:
            return testcase
    raise AssertionError(f"no probe of {name} reaches its defect")


def run(tmp_path: Path, testcase: TestCase, defects: str):
    policy = tmp_path / f"{testcase.id}.xml"
    policy.write_bytes(testcase.to_xml())
    run_dir = tmp_path / f"run-{testcase.id}-{defects}"
    res = run_proxy(ZOO_SPEC_PATH, "--policy", str(policy), "--record", str(tmp_path / f"{testcase.id}-{defects}.mcap"),
                    "--run-dir", str(run_dir), "--param", f"defects={defects}", "--param", f"seconds={SECONDS}",
                    "--duration", "20")
    return res, (run_dir / "consumer.log").read_text() if (run_dir / "consumer.log").exists() else ""


@pytest.mark.parametrize("name", SEMANTIC)
def test_each_family_s_case_reaches_its_defect_on_the_live_stack(tmp_path, name):
    testcase = family_case(name)
    res, consumer_log = run(tmp_path, testcase, "1")
    verdict = next((line for line in res.stdout.splitlines() if line.startswith("verdict:")), res.stdout + res.stderr)
    assert "Traceback" in consumer_log, (testcase.description, consumer_log, verdict)
    check, exception = raised(consumer_log)
    where, begins = RAISES[name]
    assert check == where and exception.startswith(begins), (testcase.description, consumer_log, verdict)
    assert not verdict.startswith("verdict: Pass"), verdict


def test_the_same_cases_with_the_defects_off_leave_the_run_clean(tmp_path):
    policies = tuple(replace(family_case(name).policies[0], id=f"p{k}") for k, name in enumerate(SEMANTIC, 1))
    testcase = TestCase(id="zoo-all", seed=1, description="every semantic family's case at once", policies=policies)
    res, consumer_log = run(tmp_path, testcase, "0")
    assert "verdict: Pass" in res.stdout, res.stdout + res.stderr + consumer_log
    assert "Traceback" not in consumer_log
