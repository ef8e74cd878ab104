"""A campaign folder is data: tampered journals and campaign folders through export, verify, --status and report.

A campaign folder travels (CI artefacts, a colleague's results, a bug
report). Each test here takes a real campaign of tests/sut/steady.yaml (one
confirmed bucket, B001), tampers its SQLite journal or its files as a
hostile sender would, and runs the commands a receiver runs on it: nothing
named in the folder runs as code (no marker file appears), nothing is
written outside it, no traceback, no hang, exit codes from the documented
set, no process left.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from astaa_deft.orchestration.verify.revision import describe

from cli_in_process import run_in_process
from test_verify import STEADY, run_campaign

SUT = Path(__file__).parent / "sut"
JOURNAL = "journal.sqlite"
PYTHON_ID = "B001(regress_suite=__import__('os').system('touch {marker}'), tmp_path=None) -> 1 or "


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("hostile") / "campaign"
    run_campaign(out, STEADY, {"crash_on_nan": ["1"]})
    return out


@pytest.fixture
def camp(campaign: Path, tmp_path: Path) -> Path:
    """A fresh copy of the campaign, to tamper with."""
    copy = tmp_path / "received" / "camp"
    shutil.copytree(campaign, copy)
    return copy


def sql(camp: Path, statement: str, *args: object) -> None:
    db = sqlite3.connect(camp / JOURNAL)
    try:
        db.execute(statement, args)
        db.commit()
    finally:
        db.close()


def cli(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "astaa_deft.cli", *args], capture_output=True, text=True,
                          timeout=timeout)


def in_process(*args: str) -> tuple[int, str]:
    """The command run in this process (the family below runs hundreds): exit code and stderr. A traceback
    escaping ``main`` fails the test; argparse's own usage errors exit 2."""
    return run_in_process(*args)


def tree(root: Path, *, skip: tuple[Path, ...] = ()) -> set[str]:
    """Every path under ``root`` but those under ``skip``: what a command may not add to."""
    out = set()
    for folder, dirs, files in os.walk(root):
        here = Path(folder)
        dirs[:] = [d for d in dirs if not any(here / d == s for s in skip)]
        out.update(str(here / name) for name in dirs + files)
    return out


def no_child_left() -> list[psutil.Process]:
    """This test process's descendants still alive 5 s after a command (none should be)."""
    deadline = time.monotonic() + 5
    while True:
        left = [p for p in psutil.Process().children(recursive=True) if p.is_running()
                and p.status() != psutil.STATUS_ZOMBIE]
        if not left or time.monotonic() > deadline:
            return left
        time.sleep(0.2)


# -- 1. journal text never runs as Python --------------------------------------------------------------------
def test_a_bucket_id_written_as_python_is_refused_by_every_command_and_runs_nothing(camp: Path, tmp_path: Path):
    marker = tmp_path / "MARKER"
    hostile = PYTHON_ID.format(marker=marker)
    sql(camp, "UPDATE buckets SET bucket=?", hostile)
    for args in (["export", str(camp), "-o", str(tmp_path / "regress"), "--spec", str(STEADY)],
                 ["verify", str(camp), "--spec", str(STEADY), "--runs", "1"],
                 ["fuzz", "--status", "-o", str(camp)], ["report", str(camp)]):
        done = cli(*args)
        assert done.returncode == 2, (args, done.stdout, done.stderr)
        assert "Traceback" not in done.stderr and "buckets[" in done.stderr and JOURNAL in done.stderr, done.stderr
        assert "a name that becomes a file name" in done.stderr, done.stderr
    assert not marker.exists()
    assert not (tmp_path / "regress").exists()


def test_generated_live_tests_carry_journal_text_only_as_literals(camp: Path, tmp_path: Path):
    # A culprit (shown, never a name) with quotes, braces and a newline: the suite compiles, the text is a literal.
    marker = tmp_path / "MARKER"
    culprit = f"x\"}}{{__import__('os').system('touch {marker}')}}\n'''"
    sql(camp, "INSERT INTO minimisations(bucket, status, exit_code, culprit) VALUES ('B001', 'done', 1, ?)", culprit)
    regress = tmp_path / "regress"
    done = cli("export", str(camp), "-o", str(regress), "--spec", str(STEADY), "--check", "none")
    assert done.returncode == 0, done.stdout + done.stderr
    source = (regress / "test_live.py").read_text()
    compile(source, "test_live.py", "exec")
    collected = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider",
                                str(regress)], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert collected.returncode == 0 and "test_live.py::test_B001_x_import_os_system" in collected.stdout, collected.stdout
    assert not marker.exists()


# -- 2. names from the journal never leave the command's folder ----------------------------------------------
@pytest.mark.parametrize("bucket", ["../../victim/X", "/tmp/victim-abs/X", "a/b", "B\x001", "B" * 1000, 'B"1',
                                    "B\n1", ".hidden", "B001 ", ""])
def test_bucket_ids_that_are_no_file_names_are_refused_and_nothing_is_written_outside(camp: Path, tmp_path: Path,
                                                                                       bucket: str):
    sql(camp, "UPDATE buckets SET bucket=?", bucket)
    before = tree(tmp_path)
    code, err = in_process("export", str(camp), "-o", str(tmp_path / "out" / "regress"), "--spec", str(STEADY))
    assert code == 2 and "buckets[" in err and "a name that becomes a file name" in err, err
    code, err = in_process("verify", str(camp), "--spec", str(STEADY), "--runs", "1")
    assert code == 2 and "buckets[" in err, err
    assert tree(tmp_path) - before <= {str(camp / "journal.sqlite-shm"), str(camp / "journal.sqlite-wal")}
    assert not Path("/tmp/victim-abs").exists()


# -- 3. module tests only from inside the campaign, run only as data --------------------------------------------
def test_module_tests_a_row_places_outside_the_campaign_are_neither_copied_nor_run(camp: Path, tmp_path: Path):
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "test_evil.py").write_text(f"open({str(tmp_path / 'MARKER')!r}, 'w')\n")
    for place in (str(foreign), str(camp / ".." / "foreign"), "../foreign"):
        sql(camp, "INSERT OR REPLACE INTO module_tests VALUES ('B001', ?, 1, 'fail on the defect')", place)
        for args in (["verify", str(camp), "--spec", str(STEADY), "--runs", "1"],
                     ["export", str(camp), "-o", str(tmp_path / "regress"), "--spec", str(STEADY)]):
            code, err = in_process(*args)
            assert code == 2 and "module_tests[B001].tests_dir" in err and "outside the campaign" in err, err
    link = camp / "tests-link"
    link.symlink_to(foreign)
    sql(camp, "INSERT OR REPLACE INTO module_tests VALUES ('B001', ?, 1, 'x')", str(link))
    code, err = in_process("verify", str(camp), "--spec", str(STEADY), "--runs", "1")
    assert code == 2 and "outside the campaign" in err, err
    assert not (tmp_path / "MARKER").exists()


def test_module_tests_inside_the_campaign_run_as_data_with_the_users_spec(camp: Path, tmp_path: Path):
    # A suite folder inside the campaign holding what pytest would run besides the suite's data: a conftest.py,
    # a test module, and a manifest whose embedded spec names a factory of its own, importable beside it.
    marker = tmp_path / "MARKER"
    suite = camp / "minimise" / "B001" / "tests"
    suite.mkdir(parents=True)
    evil = f"open({str(marker)!r}, 'w').write('ran')\n"
    (suite / "conftest.py").write_text(evil)
    (suite / "test_evil.py").write_text(evil + "def test_x():\n    pass\n")
    (suite / "evil_factory.py").write_text(evil + "class Boom:\n    pass\n")
    spec_text = STEADY.read_text() + ("planner: {module: worker, inputs: [aux], trigger: aux, output: data, "
                                      "replay: {factory: 'evil_factory:Boom'}}\n")
    (suite / "deft.json").write_text(json.dumps({"version": 1, "spec_name": "evil", "spec_yaml": spec_text,
                                                 "spec_dir": str(suite), "params": {}, "threshold": 0.0,
                                                 "frames": [], "oracles": [{"kind": "invariant"}]}))
    (suite / "frames.mcap").write_bytes(b"")
    sql(camp, "INSERT OR REPLACE INTO module_tests VALUES ('B001', ?, 1, 'fail on the defect')", str(suite))
    done = cli("verify", str(camp), "--spec", str(STEADY), "--runs", "1", "--label", "v1", timeout=240)
    assert done.returncode in (0, 1, 3), done.stdout + done.stderr
    assert "Traceback" not in done.stderr
    copied = next((camp / "verify").glob("*/B001/tests"))
    assert sorted(p.name for p in copied.iterdir()) == ["deft.json", "frames.mcap", "pytest.ini"]
    assert json.loads((copied / "deft.json").read_text())["spec_yaml"] == STEADY.read_text()
    assert not marker.exists()
    assert no_child_left() == []


# -- 4. what runs is what the user's command line names --------------------------------------------------------
def test_verify_and_export_refuse_the_spec_the_journal_names_unless_trusted(camp: Path, tmp_path: Path):
    marker = tmp_path / "MARKER"
    other = tmp_path / "other.yaml"
    other.write_text(STEADY.read_text().replace('command: ["{python}", "{spec_dir}/talker.py", "--key", "steady/data"',
                                                f'command: ["touch", "{marker}", "--key", "steady/data"', 1)
                     .replace("{spec_dir}", str(SUT)))
    sql(camp, "UPDATE meta SET value=? WHERE key='spec'", json.dumps(str(other)))
    for args in (["verify", str(camp), "--runs", "1"], ["export", str(camp), "-o", str(tmp_path / "regress")]):
        done = cli(*args)
        assert done.returncode == 2, done.stdout + done.stderr
        assert "--trust-journal-spec" in done.stderr and "--spec FILE" in done.stderr, done.stderr
        assert f"would run module 'talker': touch {marker}" in done.stderr, done.stderr
    done = cli("fuzz", "--resume", "-o", str(camp), "--cases", "1")
    assert done.returncode == 2 and "--trust-journal-spec" in done.stderr, done.stdout + done.stderr
    assert f"would run module 'talker': touch {marker}" in done.stderr, done.stderr
    assert not marker.exists()
    done = cli("verify", str(camp), "--runs", "1", "--spec", str(STEADY), "--trust-journal-spec")
    assert done.returncode == 2 and "not allowed with" in done.stderr, done.stderr


def test_git_runs_no_program_the_checkout_configures(tmp_path: Path):
    repo = tmp_path / "stack"
    repo.mkdir()

    def git(*args: str) -> None:
        subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True)

    git("init", "-q")
    git("config", "user.email", "a@b")
    git("config", "user.name", "a")
    (repo / "data.txt").write_text("one\n")
    (repo / ".gitattributes").write_text("*.txt filter=evil\n")
    git("add", ".")
    git("commit", "-qm", "r0")
    markers = {name: tmp_path / name for name in ("FSMONITOR", "CLEAN", "PROCESS", "HOOK")}
    git("config", "core.fsmonitor", f"touch {markers['FSMONITOR']}; false")
    git("config", "filter.evil.clean", f"touch {markers['CLEAN']}; cat")
    git("config", "filter.evil.process", f"touch {markers['PROCESS']}")
    hooks = repo / ".git" / "hooks"
    (hooks / "post-checkout").write_text(f"#!/bin/sh\ntouch {markers['HOOK']}\n")
    (hooks / "post-checkout").chmod(0o755)
    (repo / "data.txt").write_text("two\n")  # dirty: describe --dirty refreshes the index (fsmonitor, filters)
    label = describe(repo)
    assert label.endswith("-dirty"), label
    assert [name for name, path in markers.items() if path.exists()] == []


# -- 5. verify writes nothing the journal's reader later refuses; numbers bounded as on the command line ----
def test_verify_refuses_a_param_or_label_the_journal_could_not_read_back_and_the_campaign_stays_readable(
        camp: Path):
    for args in (["--param", "crash_on_nan=" + "1" * 10_001], ["--label", "v" * 10_001], ["--label", "a\nb"]):
        code, err = in_process("verify", str(camp), "--spec", str(STEADY), "--runs", "1", *args)
        assert code == 2 and "Traceback" not in err, err
    assert in_process("fuzz", "--status", "-o", str(camp))[0] == 0
    assert in_process("report", str(camp))[0] == 0


@pytest.mark.parametrize(("key", "value"), [("horizon", 1e308), ("horizon", -1), ("workers", 10**9),
                                            ("workers", 0)])
def test_journal_settings_are_bounded_as_the_command_line_bounds_them(camp: Path, key: str, value: float):
    sql(camp, "INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)", key, json.dumps(value))
    for args in (["verify", str(camp), "--spec", str(STEADY), "--runs", "1"], ["fuzz", "--status", "-o", str(camp)]):
        code, err = in_process(*args)
        assert code == 2 and f"meta[{key}]" in err, err
    assert no_child_left() == []


def test_journal_params_the_users_spec_does_not_declare_are_refused(camp: Path):
    sql(camp, "UPDATE cases SET params=?", json.dumps({"crash_on_nan": "1", "evil": "x"}))
    code, err = in_process("verify", str(camp), "--spec", str(STEADY), "--runs", "1")
    assert code == 2 and "declares no param evil" in err and "params" in err, err


def test_a_journal_with_a_million_buckets_is_refused_at_once(camp: Path):
    db = sqlite3.connect(camp / JOURNAL)
    row = db.execute("SELECT * FROM buckets").fetchone()
    names = [d[0] for d in db.execute("SELECT * FROM buckets").description]
    at = names.index("bucket")
    db.executemany(f"INSERT INTO buckets VALUES ({', '.join('?' * len(names))})",
                   ([*row[:at], f"B{n}", *row[at + 1:]] for n in range(2, 1_000_002)))
    db.commit()
    db.close()
    for args in (["verify", str(camp), "--spec", str(STEADY), "--runs", "1", "--bucket", "B001"],
                 ["fuzz", "--status", "-o", str(camp)], ["report", str(camp)]):
        done = cli(*args, timeout=60)  # a hang fails here
        assert done.returncode == 2 and "1,000,001 buckets" in done.stderr, done.stderr


def test_verify_with_nothing_verified_exits_not_observed(camp: Path):
    sql(camp, "UPDATE buckets SET without_mutation=1")
    code, err = in_process("verify", str(camp), "--spec", str(STEADY), "--runs", "1")
    assert code == 3, err


# -- 6. export owns only what it wrote -------------------------------------------------------------------------
def test_export_deletes_nothing_it_did_not_write(camp: Path, tmp_path: Path):
    regress = tmp_path / "regress"
    (regress / "cases").mkdir(parents=True)
    (regress / "regress.json").write_text("{}")
    (regress / "cases" / "mine.xml").write_text("<mine/>")
    code, err = in_process("export", str(camp), "-o", str(regress), "--spec", str(STEADY), "--check", "none")
    assert code == 4 and "not a regression suite astaa-deft export wrote" in err, err
    assert (regress / "cases" / "mine.xml").read_text() == "<mine/>"
    fresh = tmp_path / "fresh"
    assert in_process("export", str(camp), "-o", str(fresh), "--spec", str(STEADY), "--check", "none")[0] == 0
    assert in_process("export", str(camp), "-o", str(fresh), "--spec", str(STEADY), "--check", "none")[0] == 0
    (fresh / "cases" / "mine.xml").write_text("<mine/>")
    (fresh / "README.md").write_text("my notes")
    code, err = in_process("export", str(camp), "-o", str(fresh), "--spec", str(STEADY), "--check", "none")
    assert code == 4 and "cases/mine.xml" in err and "README.md" in err, err
    assert (fresh / "cases" / "mine.xml").exists() and (fresh / "README.md").read_text() == "my notes"


def test_a_link_at_the_campaigns_verify_folder_is_not_written_through(camp: Path, tmp_path: Path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (camp / "verify").symlink_to(elsewhere)
    code, err = in_process("verify", str(camp), "--spec", str(STEADY), "--runs", "1", "--label", "v1")
    assert code == 4 and "symbolic link" in err, err
    assert list(elsewhere.iterdir()) == []


# -- 7. the spec reader holds liveliness, provenance and ready to the rules of other keys -------------------
@pytest.mark.parametrize(("line", "expected"), [
    ("liveliness: [{key: '', producer: talker}]", "liveliness key is empty"),
    ("liveliness: [{key: \"steady/a\\0b\", producer: talker}]", "not a concrete Zenoh key"),
    ("liveliness: [{key: steady/alive/, producer: talker}]", "not a concrete Zenoh key"),
    ("liveliness: [{key: " + "k" * 100_000 + ", producer: talker}]", "characters long"),
    ("planner: {module: worker, inputs: [aux], trigger: aux, output: data, replay: {factory: 'm:F'}, "
     "provenance: " + "a." * 500_000 + "b}", "characters long"),
    ("planner: {module: worker, inputs: [aux], trigger: aux, output: data, replay: {factory: 'm:F'}, "
     "provenance: debug.inputs}", "no field"),
])
def test_the_spec_holds_liveliness_provenance_and_ready_to_the_rules(tmp_path: Path, line: str, expected: str):
    spec = tmp_path / "spec.yaml"
    spec.write_text(STEADY.read_text().replace("{spec_dir}", str(SUT)) + line + "\n")
    code, err = in_process("spec", "check", str(spec))
    assert code == 2 and expected in err and "Traceback" not in err, err


def test_an_empty_ready_log_pattern_is_refused(tmp_path: Path):
    spec = tmp_path / "spec.yaml"
    spec.write_text(STEADY.read_text().replace('ready: {log: "worker ready"}', "ready: {log: ''}"))
    code, err = in_process("spec", "check", str(spec))
    assert code == 2 and "'ready.log' is empty" in err, err


# -- 8. a generated family of tampered journals (the default run: 40; -m slow: 1,000) -----------------------------
HOSTILE_TEXT = ["../../victim/X", "/tmp/victim-abs/Y", "a/b", "x\x00y", "Z" * 1000, "q\"'{}\n", "$(touch {m})",
                "__import__('os').system('touch {m}')", "", " ", "B001", "..", "é", "\udcff"]
HOSTILE_NUMBERS = [-1, 1e308, float("nan"), -(2**63), "x", None, 2**63 - 1, 0.5]
COLUMNS = {
    "buckets": ["bucket", "signature", "verdict", "invariant", "module", "family", "first_case", "without_mutation",
                "cases", "reruns", "merged_into", "created_at", "kind"],
    "cases": ["case_id", "kind", "params", "testcase_xml", "strategy", "parent", "status", "bucket", "outcome",
              "log_path", "at_once", "seconds"],
    "meta": ["spec", "horizon", "workers", "params", "seed", "overloaded_runs"],
}
COMMANDS = (("fuzz", "--status", "-o", "{camp}"), ("report", "{camp}"),
            ("export", "{camp}", "-o", "{out}", "--spec", str(STEADY), "--check", "none"))
# Commands that run the stack when the tampering is not refused first (live runs, module tests): on some cases.
RUNNING = (("verify", "{camp}", "--spec", str(STEADY), "--runs", "1", "--label", "v1"),
           ("export", "{camp}", "-o", "{out}2", "--spec", str(STEADY), "--check", "module"),
           ("fuzz", "--resume", "-o", "{camp}", "--spec", str(STEADY), "--no-minimise"))


def tamper(camp: Path, rng: random.Random, marker: Path) -> str:
    """One hostile cell written into the journal; what was done, for the failure message."""
    table = rng.choice(sorted(COLUMNS))
    column = rng.choice(COLUMNS[table])
    value: object = rng.choice(HOSTILE_TEXT + HOSTILE_NUMBERS) if rng.random() < 0.8 else \
        json.dumps(rng.choice(HOSTILE_TEXT + HOSTILE_NUMBERS))
    if isinstance(value, str):
        value = value.replace("{m}", str(marker))
        if "\udcff" in value:
            value = value.encode("utf-8", "surrogateescape")
    try:
        if table == "meta":
            sql(camp, "INSERT OR REPLACE INTO meta(key, value) VALUES (?, ?)", column,
                value if isinstance(value, (str, bytes)) else json.dumps(value))
        else:
            sql(camp, f"UPDATE {table} SET {column}=?", value)
    except sqlite3.IntegrityError:  # a NOT NULL column: SQLite itself keeps that cell
        return f"{table}.{column}: kept by SQLite"
    return f"{table}.{column} = {value!r}"[:200]


def run_family(campaign: Path, tmp_path: Path, cases: int, seed: int, running_every: int) -> None:
    rng = random.Random(seed)
    marker = tmp_path / "MARKER"
    for n in range(cases):
        case_dir = tmp_path / f"case{n}"
        camp = case_dir / "camp"
        shutil.copytree(campaign, camp)
        done = [tamper(camp, rng, marker) for _ in range(rng.randint(1, 3))]
        before = tree(tmp_path, skip=(camp,))
        for command in COMMANDS + (RUNNING if n % running_every == 0 else ()):
            args = [a.format(camp=camp, out=case_dir / "regress") for a in command]
            code, err = in_process(*args)
            assert code in (0, 1, 2, 3, 4), (done, args, code, err)
        after = tree(tmp_path, skip=(camp, case_dir / "regress", case_dir / "regress2"))
        assert after == before, (done, sorted(after - before)[:5])
        assert not marker.exists(), done
        assert no_child_left() == [], done
        shutil.rmtree(case_dir)


def test_a_family_of_tampered_journals_gives_no_traceback_no_marker_and_no_write_outside(campaign: Path,
                                                                                          tmp_path: Path):
    run_family(campaign, tmp_path, cases=40, seed=1, running_every=10)


@pytest.mark.slow
def test_a_thousand_tampered_journals_give_no_traceback_no_marker_and_no_write_outside(campaign: Path,
                                                                                       tmp_path: Path):
    run_family(campaign, tmp_path, cases=1000, seed=2, running_every=10)
