"""Extraction is pinned on recorded zoo runs: the frame rules and the extraction give byte-identical results.

The committed logs (``tests/data/extraction_pins``, one short run of each of
five zoo members and one of the bundled demo) are extracted as a user would (``astaa-deft extract LOG
--spec SPEC --module module --threshold 0``): every file of the suite is the
one pinned, and so is every candidate frame the frame rules propose for
every output of each log (``tests/extraction_pins.py`` says how the pins are
made, and how a change meant to alter extraction rewrites them).
"""

from __future__ import annotations

import pytest

from extraction_pins import (
    DEMO, EXTRACTED, MEMBERS, candidate_lines, committed, demo_pins_now, digest, member_stack, pins_now,
)


@pytest.mark.parametrize("name", MEMBERS)
def test_the_frame_rules_propose_the_pinned_candidates_for_every_output_of_a_recorded_run(name, tmp_path):
    stack, log = member_stack(name, tmp_path)
    lines = list(candidate_lines(log, stack.spec_path))
    assert sum(line.startswith("output ") for line in lines) > 20  # a run's outputs, each with its candidates
    assert digest(iter(lines)) == committed()[name]["candidates"]


@pytest.mark.parametrize("name", EXTRACTED)
def test_extraction_of_a_recorded_run_writes_the_pinned_suite_byte_for_byte(name, tmp_path):
    pins = committed()[name]
    now = pins_now(name, tmp_path)
    assert (now["exact"], now["tests"]) == (pins["exact"], pins["tests"])
    assert now["suite"] == pins["suite"]
    assert set(now["suite"]) >= {"deft.json", "frames.mcap"}



def test_the_demo_planner_extracted_from_a_recorded_run_keeps_the_pinned_frames(tmp_path):
    pins, now = committed()[DEMO], demo_pins_now(tmp_path)
    assert now["tests"] > 50 and now["exact"] == pins["exact"]
    assert now == pins
