"""The plant (a module the spec marks ``plant: true``: the simulator, the world the stack drives) is never to blame.

A mutated control command goes straight into the plant, which applies it faithfully: its output departs first,
and what caused the failure is the mutated value itself, not a module under test. Pure logic over ``RunSeries``
(blame.py) and the spec's ``plant:`` key.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.model.errors import InputError
from astaa_deft.orchestration.campaign.blame import Blame, RunSeries, blame
from astaa_deft.orchestration.journal.rows import MUTATED_VALUE, THE_MUTATED_VALUE, BlameRow, root_cause_of

from blame_series import series

NAN = float("nan")

# A closed loop: control → command → sim (the plant) → pose → control and watcher; guard also reads the command.
LOOP = """\
name: loop
modules:
  - name: sim
    command: ["{python}", "-c", "pass"]
    plant: true
  - name: control
    command: ["{python}", "-c", "pass"]
  - name: guard
    command: ["{python}", "-c", "pass"]
  - name: watcher
    command: ["{python}", "-c", "pass"]
channels:
  - {name: command, key: loop/command, producer: control, consumers: [sim, guard], type: Msg}
  - {name: pose, key: loop/pose, producer: sim, consumers: [control, watcher], type: Msg}
  - {name: check, key: loop/check, producer: guard, consumers: [], type: Msg}
  - {name: alert, key: loop/alert, producer: watcher, consumers: [], type: Msg}
types:
  Msg: {v: float64}
"""


@pytest.fixture
def loop(tmp_path: Path):
    path = tmp_path / "loop.yaml"
    path.write_text(LOOP)
    return load_spec(path)


CALM = [1.0] * 40
TWINS = [series({"command": CALM, "pose": CALM, "check": CALM, "alert": CALM}),
         series({"command": CALM, "pose": CALM, "check": CALM, "alert": CALM})]


def nan_from(step: int) -> list[float | None]:
    return [*CALM[:step], *[NAN] * (40 - step)]


def test_the_plant_departing_first_blames_the_mutated_value_itself_and_the_chain_names_the_plant(loop):
    # The command is mutated at 2.0 s (bin 4); the plant's pose goes non-finite at 2.1 s; nothing else departs.
    failing = series({"command": CALM, "pose": nan_from(21), "check": CALM, "alert": CALM}, mutated_at=4,
                     mutated=("command",))
    found = blame(loop, failing, TWINS, invariant="finite_pose", finding_module="sim")
    assert found.module is None and found.how == MUTATED_VALUE and found.output == "pose"
    assert found.chain == ("command (mutated) → sim (plant: carries the value on) → pose (non-finite: v#nonfinite)"
                           " → finite_pose")
    assert found.detail.endswith("no module under test departed before the plant sim")
    assert found.root_cause == THE_MUTATED_VALUE
    assert found.wrong_output == f"pose:{MUTATED_VALUE}"


def test_a_module_under_test_reading_the_mutated_channel_in_the_plants_bin_is_blamed(loop):
    # guard reads the mutated command too, and its check departs in the same bin as the plant's pose.
    failing = series({"command": CALM, "pose": nan_from(21), "check": nan_from(23), "alert": CALM}, mutated_at=4,
                     mutated=("command",))
    found = blame(loop, failing, TWINS, invariant="finite_pose", finding_module="sim")
    assert found.module == "guard" and found.output == "check" and found.how == "non-finite"
    assert found.chain == "command → guard → check (non-finite: v#nonfinite) → finite_pose"


def test_a_module_under_test_departing_after_the_plant_reacts_to_its_world_and_is_not_blamed(loop):
    # watcher reads the plant's pose and departs a bin later (and guard two bins later): reactions, not causes.
    failing = series({"command": CALM, "pose": nan_from(21), "check": nan_from(31), "alert": nan_from(26)},
                     mutated_at=4, mutated=("command",))
    found = blame(loop, failing, TWINS, invariant="finite_alert", finding_module="watcher")
    assert found.module is None and found.how == MUTATED_VALUE and found.output == "pose"
    assert found.chain.startswith("command (mutated) → sim (plant: carries the value on) → pose")


def test_a_module_under_test_departing_before_the_plant_is_blamed_as_before(loop):
    # The mutated pose reaches control, whose command departs first; the plant then carries the bad command on.
    failing = series({"command": nan_from(21), "pose": CALM, "check": nan_from(26), "alert": nan_from(26)},
                     mutated_at=4, mutated=("pose",))
    found = blame(loop, failing, TWINS, invariant="finite_check", finding_module="guard")
    assert found.module == "control" and found.how == "non-finite" and found.root_cause == "control"


def test_a_plant_that_reads_no_mutated_channel_is_not_blamed_either_and_loses_its_bin_to_a_module_under_test(loop):
    # check is mutated (nobody reads it); the plant's pose departs first: the value reached it some other way.
    alone = series({"command": CALM, "pose": nan_from(21), "check": CALM, "alert": CALM}, mutated_at=4,
                   mutated=("check",))
    found = blame(loop, alone, TWINS, invariant="finite_pose", finding_module="sim")
    assert found.module is None and found.how == MUTATED_VALUE
    assert found.chain.startswith("check (mutated) → … → sim (plant: departed before any module under test) → pose")
    # watcher's alert departs in the same bin: neither reads the mutated channel, the module under test goes first.
    both = series({"command": CALM, "pose": nan_from(21), "check": CALM, "alert": nan_from(22)}, mutated_at=4,
                  mutated=("check",))
    assert blame(loop, both, TWINS, invariant="finite_pose", finding_module="sim").module == "watcher"


def test_with_no_departure_a_finding_naming_the_plant_blames_the_value_it_was_fed_not_the_plant(loop):
    failing = series({"command": CALM, "pose": CALM, "check": CALM, "alert": CALM}, mutated_at=4,
                     mutated=("command",))
    fed = blame(loop, failing, TWINS, invariant="sim_alive", finding_module="sim")
    assert fed.module is None and fed.how == MUTATED_VALUE and fed.output is None
    assert fed.chain.startswith("command (mutated) → sim (plant: carries the value on) → (sim_alive names it")
    unfed = blame(loop, RunSeries(failing.bins, 4, ("check",)), TWINS, invariant="sim_alive", finding_module="sim")
    assert unfed.module is None and unfed.how == "none" and unfed.root_cause is None
    assert "names sim, the plant" in unfed.chain
    assert blame(loop, failing, TWINS, invariant="x", finding_module="watcher").module == "watcher"


def test_a_stored_blame_row_names_the_same_root_cause_old_rows_included():
    plant = Blame(module=None, output="pose", how=MUTATED_VALUE, chain="c", detail="d", twins=2)
    row = BlameRow(bucket="B001", module=plant.module, output=plant.output, how=plant.how, chain=plant.chain,
                   detail=plant.detail, twins=plant.twins, identity=None)
    assert row.root_cause == plant.root_cause == THE_MUTATED_VALUE
    old = BlameRow(bucket="B002", module="planning", output="trajectory", how="value", chain="c", detail="d", twins=2,
                   identity="planning|trajectory:value|x|y")
    assert old.root_cause == "planning" and root_cause_of(None, "none") is None


def test_plant_is_read_from_the_spec_false_by_default_and_the_bundled_simulators_are_plants(loop):
    from astaa_deft.demo.bundled import demo_spec_path

    assert loop.module("sim").plant and not loop.module("control").plant
    assert loop.is_plant("sim") and not loop.is_plant("control") and not loop.is_plant(None)
    demo = load_spec(demo_spec_path())
    assert [m.name for m in demo.modules if m.plant] == ["simulator"]
    ompl = load_spec(Path(__file__).parents[1] / "examples" / "ompl_stack" / "spec.yaml")
    assert [m.name for m in ompl.modules if m.plant] == ["simulator"]


@pytest.mark.parametrize("value,says", [('"yes"', "str 'yes'"), ("1", "1"), ("[true]", "list")])
def test_a_plant_that_is_not_true_or_false_is_one_clear_error(tmp_path: Path, value: str, says: str):
    path = tmp_path / "loop.yaml"
    path.write_text(LOOP.replace("    plant: true\n", f"    plant: {value}\n"))
    with pytest.raises(InputError) as err:
        load_spec(path)
    problems = err.value.problems
    assert len(problems) == 1, [str(p) for p in problems]
    problem = problems[0]
    assert problem.file == str(path) and problem.line == 5 and problem.column is not None
    assert "'plant' must be true or false" in problem.message and says in problem.message
    assert "true or false" in (problem.fix or "")


def test_a_bucket_blamed_on_the_mutated_value_gets_no_module_tests_and_an_unknown_blame_falls_back(tmp_path: Path):
    from astaa_deft.demo.bundled import demo_spec_path
    from astaa_deft.orchestration.campaign.campaign import Campaign, CampaignConfig
    from astaa_deft.orchestration.journal.journal import Bucket, Journal

    def bucket(name: str, module: str) -> Bucket:
        return Bucket(bucket=name, signature="sig", verdict="Silent", invariant="speed_limit", module=module,
                      family="command:acceleration:set", first_case="c-000001", without_mutation=False, cases=1,
                      reruns=0, rerun_failures=0, merged_into=None, created_at=0.0, created_after_cases=1)

    journal = Journal(tmp_path / "c")
    try:
        campaign = Campaign(CampaignConfig(spec_path=demo_spec_path(), out=tmp_path / "c"), journal, say=print)
        journal.blamed(BlameRow(bucket="B001", module=None, output="localization", how=MUTATED_VALUE, chain="c",
                                detail="d", twins=2, identity="x"))
        journal.blamed(BlameRow(bucket="B002", module=None, output=None, how="none", chain="c", detail="d", twins=2,
                                identity=None))
        # No module under test mishandled the value: not even the finding's module (a reaction) gets tests.
        assert campaign._module_to_replay(bucket("B001", "planning")) is None
        assert campaign._module_to_replay(bucket("B002", "planning")) == "planning"  # blame unknown: the finding's
        assert campaign._module_to_replay(bucket("B003", "simulator")) is None  # the plant, and no replay of it
    finally:
        journal.close()
