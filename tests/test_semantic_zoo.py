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
# What the consumer's traceback says for each family's defect (tests/sut/zoo_consumer.py).
SAYS = {"boundary": "IndexError", "angle": "angle defect", "units": "units defect", "arrays": "arrays defect",
        "type": "Error", "siblings": "siblings defect", "stale": "ZeroDivisionError"}


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
    assert "Traceback" in consumer_log and SAYS[name] in consumer_log, (testcase.description, consumer_log, verdict)
    assert not verdict.startswith("verdict: Pass"), verdict


def test_the_same_cases_with_the_defects_off_leave_the_run_clean(tmp_path):
    policies = tuple(replace(family_case(name).policies[0], id=f"p{k}") for k, name in enumerate(SEMANTIC, 1))
    testcase = TestCase("zoo-all", 1, "every semantic family's case at once", policies)
    res, consumer_log = run(tmp_path, testcase, "0")
    assert "verdict: Pass" in res.stdout, res.stdout + res.stderr + consumer_log
    assert "Traceback" not in consumer_log
