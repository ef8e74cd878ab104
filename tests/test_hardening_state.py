"""Generated tampered state files: checkpoints and journals are input like any other.

Two families, each drawn by a seeded generator from a real state file the tool wrote:

* **checkpoint** — the ``extraction.json`` an interrupted ``extract`` left (toy planner, 30 outputs, stopped
  at 10), tampered: values of the wrong type, out of range or non-finite, fields removed or unknown, other
  versions, JSON nested 100,000 deep, cut or not JSON, more entries than the log has outputs, links (to a
  device, a folder, a FIFO, nowhere); run through ``extract --resume``.
* **journal** — a campaign's ``journal.sqlite`` (meta, cases with outcomes, a bucket, a minimisation, module
  tests, notes), tampered through SQLite itself: any cell of any table set to text, big or negative numbers,
  blobs, deep or broken JSON; meta values that are not JSON or not the type; unknown kinds (a newer version);
  columns and tables dropped; the file cut or overwritten; links; run through ``fuzz --status`` and
  ``report``.

Every case runs ``astaa_deft.cli.main`` in the capped worker of test_hardening_generated (each case with
its own timeout). Asserted for every case: no traceback, no hang, exit 2 naming the state file (or 0 for a
state still valid; 4 only for a link the tool would have written through). The default run draws a few
dozen cases per family; ``pytest -m slow`` draws 1,000 each and prints the figures.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import sqlite3
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from test_hardening_generated import CASE_TIMEOUT_S, _env, _limits

HERE = Path(__file__).resolve().parent
HOSTILE = [None, True, False, -1, 0, 1.5, -0.0, 10**30, -10**30, 2**63, 2**64, float("inf"), float("-inf"),
           float("nan"), "x", "", "../../x", "9" * 400, [], {}, [1, 2, 3], {"a": 1}, {"pose": -1}, [[[[]]]]]
DEEP = "[" * 100_000 + "]" * 100_000
RAW_TOKENS = [DEEP, "1e999", "-1e999", "NaN", "Infinity", "1" + "0" * 400, '"\\ud800"', "{", "]", "\x00", "\ufeff",
              '{"a":' * 5000 + "1" + "}" * 5000]


# -- checkpoint ------------------------------------------------------------------------------------
def make_checkpoint(work: Path) -> tuple[Path, Path, Path]:
    """A real interrupted extraction: (spec, log, its output folder holding extraction.json)."""
    sys.path[:0] = [str(HERE), str(HERE / "sut")]
    try:
        from toy_run import toy_log

        from astaa_deft.analysis.deft.workflow import ExtractOptions, extract_module_tests

        spec, log = toy_log(work, cycles=30)

        def stop(done: int, total: int) -> None:
            if done == 10:
                raise KeyboardInterrupt

        out = work / "base-out"
        report = extract_module_tests(log, spec, out, ExtractOptions(jobs=1), progress=stop)
        assert report.interrupted and (out / "extraction.json").is_file()
    finally:
        del sys.path[:2]
    return spec, log, out


def _paths(value, prefix=()):
    """Every (path, container) in a JSON value: where a tampering can land."""
    yield prefix
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _paths(v, prefix + (i,))


def _at(value, path):
    for step in path:
        value = value[step]
    return value


def tamper_json(state: dict, rng: random.Random) -> str:
    """1–3 tamperings of a state: a JSON text (possibly no longer JSON at all)."""
    state = json.loads(json.dumps(state))
    raw: list[str] = []
    for _ in range(rng.randint(1, 3)):
        paths = [p for p in _paths(state) if p]
        op = rng.randrange(9)
        path = rng.choice(paths)
        parent, key = _at(state, path[:-1]), path[-1]
        if op in (0, 1, 2):
            parent[key] = rng.choice(HOSTILE)
        elif op == 3 and isinstance(parent, dict):
            del parent[key]
        elif op == 4:
            target = rng.choice([p for p in _paths(state) if isinstance(_at(state, p), dict)])
            _at(state, target)[rng.choice(["zz", "../../x", "pose", "tick", "", "skipped"])] = rng.choice(HOSTILE)
        elif op == 5:
            state["version"] = rng.choice([0, 2, 99, "1", 1.0, None, -1])
        elif op == 6:
            state["extraction"] = dict(state.get("extraction") or {}, **{rng.choice(
                ["log", "spec", "module", "threshold", "log_bytes"]): rng.choice(HOSTILE)}) \
                if isinstance(state.get("extraction"), dict) else rng.choice(HOSTILE)
        elif op == 7 and isinstance(state.get("decided"), list) and state["decided"]:
            state["decided"] = state["decided"] * rng.choice([2, 5, 200])
        else:
            raw.append(rng.choice(RAW_TOKENS))
    text = json.dumps(state)
    for token in raw:  # a token where a value was: most often no longer JSON, or nested 100k deep
        marker = rng.choice(['"accepted": ', '"pose": ', '"version": ', '"decided": ', '"distance": '])
        text = text.replace(marker, marker + token + (", \"_\": " if rng.random() < 0.5 else ""), 1) \
            if rng.random() < 0.8 else text[:rng.randrange(len(text))]
    return text


def checkpoint_cases(count: int, rng: random.Random, work: Path) -> list[dict]:
    spec, log, base = make_checkpoint(work)
    state = json.loads((base / "extraction.json").read_text())
    argv = lambda out: ["extract", str(log), "--spec", str(spec), "-o", str(out), "--resume", "--jobs", "1"]  # noqa: E731
    cases = []
    for n in range(count):
        out = work / f"case{n:05d}"
        shutil.copytree(base, out)
        target = out / "extraction.json"
        if n % 25 == 7:  # links: a device, a folder, a FIFO, nowhere, a valid copy elsewhere
            target.unlink()
            kind = (n // 25) % 5
            if kind == 0:
                target.symlink_to("/dev/zero")
            elif kind == 1:
                target.symlink_to(work)
            elif kind == 2:
                fifo = work / f"fifo{n}"
                os.mkfifo(fifo)
                target.symlink_to(fifo)
            elif kind == 3:
                target.symlink_to(work / "nowhere.json")
            else:
                copy = work / f"copy{n}.json"
                copy.write_text(json.dumps(state))
                target.symlink_to(copy)
            cases.append({"name": f"link{kind}-{n}", "argv": argv(out), "state": str(target)})
            continue
        target.write_text(tamper_json(state, rng), encoding="utf-8", errors="surrogatepass")
        cases.append({"name": f"checkpoint{n}", "argv": argv(out), "state": str(target)})
    return cases


# -- journal ---------------------------------------------------------------------------------------
FUZZ_SPEC = """\
name: tiny
params:
  scenario: {choices: [a, b]}
modules: [{name: a, command: "true"}, {name: b, command: "true"}]
channels: [{name: data, key: t/data, producer: a, consumers: [b], type: Sample},
           {name: routing, key: t/routing, producer: a, consumers: [b], type: Route}]
types:
  Sample: {seq: uint64, value: float64}
  Route: {speed_limit: float64}
invariants:
  - {name: value_small, kind: expression, channel: data, expr: "value < 10"}
"""


def make_journal(work: Path) -> Path:
    from test_campaign_report import _case, _signature

    from astaa_deft.orchestration.journal.journal import Journal, Minimisation, NewBucket
    from astaa_deft.orchestration.journal.model import BASELINE, MUTATED, Finding, Timing
    from astaa_deft.orchestration.journal.rows import BlameRow
    from astaa_deft.orchestration.journal.verifications import TABLE as VERIFICATIONS_TABLE

    spec = work / "fuzz.yaml"
    spec.write_text(FUZZ_SPEC)
    base = work / "base"
    journal = Journal(base)
    try:
        journal.set_meta(spec=str(spec), seed=1, strategy="random", params={"scenario": ["a", "b"]}, horizon=2.0,
                         cases=3, budget=60.0, calibrated=True, workers=2, timing=Timing("data", 1.5).__dict__,
                         overloaded_runs=["b-0001"])
        finding = Finding(invariant="value_small", crash="Silent", module="a", channel="data", detail="value 20 > 10",
                          severity="high", at=1.2)
        _case(journal, base, "b-0001", BASELINE, 1, "Pass", "goal reached")
        _case(journal, base, "c-000001", MUTATED, 1, "Silent", "violation", "B001", finding)
        _case(journal, base, "c-000002", MUTATED, 2, "Pass", "horizon")
        journal.add_bucket(NewBucket(name="B001", signature=_signature("data:value:set"), verdict="Silent",
                                     invariant="value_small", module="a", first_case="c-000001", without_mutation=False,
                                     after_cases=2))
        journal.bucket_rerun("B001", True)
        journal.minimised(Minimisation(bucket="B001", status="minimised", exit_code=0, minimal_xml="<testcase id='m'/>",
                                       culprit="data:value = 20", out_dir=str(base / "minimised" / "B001"),
                                       tests_dir=str(base / "tests" / "B001"), seconds=3.0, detail=""))
        journal.module_tests_checked("B001", str(base / "tests" / "B001"), True, "1 failed")
        journal.note("workers", "2 at once")
        journal.blamed(BlameRow(bucket="B001", module="a", output="data", how="non-finite",
                                chain="data:value -> a -> data -> value_small",
                                detail="value NaN where the twins had finite values", twins=2,
                                identity="a|data|value_small"))
        journal.db.executescript(VERIFICATIONS_TABLE)
        journal.db.execute(
            "INSERT INTO verifications (bucket, revision, status, failing, runs, other, unobserved, twin_failures,"
            " twins, module_tests, detail, params, at) VALUES ('B001', 'v1', 'fixed', 0, 3, 0, 0, 0, 3, 0, '',"
            " '{}', 1700000000.0)")
        journal.db.commit()
    finally:
        journal.close()
    return base


TABLES = ["meta", "cases", "buckets", "minimisations", "module_tests", "notes", "blames", "verifications"]
CELL_VALUES = [None, "x", "", "<img src=x onerror=alert(1)>", -1, 10**18, 2**63 - 1, -(2**63), 1.5, float("inf"),
               float("-inf"), b"\x00\xff", "9" * 400, DEEP, "{", "[]", "{}", '{"status": 1}', "null", "NaN",
               json.dumps({"status": "done", "verdict": "Pass", "summary": "s", "findings": [{"invariant": 1}]}),
               json.dumps({"status": "done", "verdict": "Pass", "summary": "s", "timing": {"c": {"count": "x"}}}),
               json.dumps({"a": "b"}), json.dumps({"a": ["b"]}), "zzz", "bug", "planned", "x" * (2 << 20)]


def tamper_journal(path: Path, rng: random.Random) -> list[str]:
    """1–3 tamperings made through SQLite; what was done, one phrase each."""
    done: list[str] = []
    db = sqlite3.connect(path)
    try:
        for _ in range(rng.randint(1, 3)):
            table = rng.choice(TABLES)
            columns = [r[1] for r in db.execute(f"PRAGMA table_info({table})")]
            if not columns:
                continue
            op = rng.randrange(10)
            try:
                if op < 7:
                    column, value = rng.choice(columns), rng.choice(CELL_VALUES)
                    db.execute(f"UPDATE {table} SET {column}=?", (value,))
                    done.append(f"{table}.{column}={str(value)[:20]!r}")
                elif op == 7:
                    column = rng.choice(columns)
                    db.execute(f"ALTER TABLE {table} DROP COLUMN {column}")
                    done.append(f"drop {table}.{column}")
                elif op == 8:
                    db.execute(f"DROP TABLE {table}")
                    done.append(f"drop {table}")
                else:
                    key = rng.choice(["seed", "params", "horizon", "timing", "calibrated", "overloaded_runs",
                                      "spec", "workers", "budget", "strategy", "cases"])
                    value = rng.choice(CELL_VALUES)
                    db.execute("UPDATE meta SET value=? WHERE key=?", (value, key))
                    done.append(f"meta[{key}]={str(value)[:20]!r}")
            except sqlite3.Error:
                pass  # a constraint the tampering broke: that one is not made
        db.commit()
    finally:
        db.close()
    return done


def journal_cases(count: int, rng: random.Random, work: Path) -> list[dict]:
    base = make_journal(work)
    cases = []
    for n in range(count):
        folder = work / f"case{n:05d}"
        shutil.copytree(base, folder)
        journal = folder / "journal.sqlite"
        command = ["fuzz", "--status", "-o", str(folder)] if n % 2 else ["report", str(folder)]
        if n % 25 == 11:  # the file itself: cut, overwritten, a link
            kind = (n // 25) % 4
            data = journal.read_bytes()
            if kind == 0:
                journal.write_bytes(data[:rng.randrange(1, len(data))])
            elif kind == 1:
                journal.write_bytes(bytes(rng.randrange(256) for _ in range(4096)))
            elif kind == 2:
                journal.unlink()
                journal.symlink_to("/dev/null")
            else:
                journal.unlink()
                journal.symlink_to(base / "journal.sqlite")
            cases.append({"name": f"file{kind}-{n}", "argv": command, "state": str(journal), "link": kind >= 2})
            continue
        done = tamper_journal(journal, rng)
        cases.append({"name": f"journal{n} ({'; '.join(done)})", "argv": command, "state": str(journal)})
    return cases


# -- running and judging ---------------------------------------------------------------------------
def run_family(family: str, count: int, seed: int, work: Path) -> list[dict]:
    rng = random.Random(f"{family}-{seed}")
    work.mkdir(parents=True, exist_ok=True)
    return run_cases((checkpoint_cases if family == "checkpoint" else journal_cases)(count, rng, work), work)


def run_cases(cases: list[dict], work: Path) -> list[dict]:
    """Each case's command run in one capped worker process (its own timeout each); the results."""
    cases_file, results_file = work / "cases.json", work / "results.json"
    cases_file.write_text(json.dumps(cases))
    proc = subprocess.run([sys.executable, str(HERE / "test_hardening_generated.py"), "worker", str(cases_file),
                           str(results_file)], capture_output=True, text=True, preexec_fn=_limits, cwd=work,
                          env=_env(), timeout=CASE_TIMEOUT_S * len(cases) + 120)
    assert proc.returncode == 0, f"the worker died: {proc.stderr[-3000:]}"
    results = json.loads(results_file.read_text())
    for case, result in zip(cases, results, strict=True):
        result["state"], result["link"] = case["state"], case.get("link", False)
    return results


def problems_in(results: list[dict]) -> list[str]:
    bad = []
    for r in results:
        text = r["stdout"] + r["stderr"]
        where = f"{r['name']} ({' '.join(r['argv'][:2])})"
        if r["traceback"] or "Traceback" in text:
            bad.append(f"{where}: traceback\n{r['traceback'] or text}")
        elif r["hang"]:
            bad.append(f"{where}: no answer within {CASE_TIMEOUT_S} s")
        elif r["code"] == 4 and not r["link"]:
            bad.append(f"{where}: exit 4 for a damaged state file (2 expected)\n{text[-800:]}")
        elif r["code"] not in (0, 2, 4):
            bad.append(f"{where}: exit {r['code']}\n{text[-800:]}")
        elif r["code"] == 2 and ("astaa-deft: error:" not in r["stderr"]
                                 or Path(r["state"]).name not in r["stderr"] and Path(r["state"]).parent.name
                                 not in r["stderr"]):
            bad.append(f"{where}: exit 2 without naming the state file\n{text[-800:]}")
    return bad


def figures(family: str, results: list[dict]) -> str:
    codes = Counter(r["code"] for r in results if not r["hang"] and not r["traceback"])
    return (f"{family}: {len(results)} cases, exit codes {dict(sorted(codes.items(), key=str))}, "
            f"tracebacks {sum(bool(r['traceback']) or 'Traceback' in r['stderr'] for r in results)}, "
            f"hangs {sum(r['hang'] for r in results)}, slowest {max(r['seconds'] for r in results):.2f} s")


@pytest.mark.parametrize("family", ["checkpoint", "journal"])
def test_tampered_state_short(family, tmp_path):
    results = run_family(family, 30, seed=20261127, work=tmp_path)
    print(figures(family, results))
    assert not problems_in(results), "\n\n".join(problems_in(results)[:5])
    # The generator really damages them (a text cell set to other text is still a valid journal, and a cell
    # the command does not read is not judged by it: not every case is refused).
    assert sum(r["code"] == 2 for r in results) >= len(results) // 3


@pytest.mark.slow
@pytest.mark.timeout(4 * 3600)
@pytest.mark.parametrize("family", ["checkpoint", "journal"])
def test_tampered_state_full(family, tmp_path):
    results = run_family(family, 1000, seed=1, work=tmp_path)
    report = figures(family, results)
    print(report)
    figures_file = os.environ.get("ASTAA_DEFT_FIGURES")
    if figures_file:
        with open(figures_file, "a") as f:
            f.write(report + "\n")
    assert len(results) >= 1000
    assert not problems_in(results), "\n\n".join(problems_in(results)[:5])


# -- tampered journals and checkpoints, one case each ----------------------------------------------------
CHECKPOINT_NAMED = {
    "a choice key ../../x": lambda s: s["decided"][0]["choice"].update({"../../x": 0}),
    "an index of 10^30": lambda s: s["decided"][0]["choice"].update({"pose": 10**30}),
    "a choice index of -1": lambda s: s["decided"][0]["choice"].update({"pose": -1}),
    "comparison fields as text": lambda s: s["decided"][0]["comparison"].update({"distance": "0.0"}),
    "2 M skipped entries": lambda s: s.update(decided=[{"output": i, "skipped": "x"} for i in range(2_000_000)]),
    "version 99": lambda s: s.update(version=99),
}


def test_the_named_checkpoint_tamperings_are_one_clear_error_each(tmp_path):
    spec, log, base = make_checkpoint(tmp_path)
    state = json.loads((base / "extraction.json").read_text())
    texts = {name: json.dumps(_edited(state, edit)) for name, edit in CHECKPOINT_NAMED.items()}
    texts["trigger_time_ns 1e999"] = json.dumps(state).replace('"trigger_time_ns": ', '"trigger_time_ns": 1e999, "_": ',
                                                              1)
    texts["nested 100,000 deep"] = '{"version": 1, "decided": ' + DEEP + "}"
    expected = {"a choice key ../../x": "decided[0].choice", "an index of 10^30": "decided[0].choice.pose",
                "a choice index of -1": "decided[0].choice.pose",
                "comparison fields as text": "decided[0].comparison.distance",
                "2 M skipped entries": "an extraction of this log writes at most",
                "version 99": "field 'version' is 99",
                "trigger_time_ns 1e999": "decided[0].trigger_time_ns", "nested 100,000 deep": "nested deeper"}
    cases = []
    for n, (name, text) in enumerate(texts.items()):
        out = tmp_path / f"named{n}"
        shutil.copytree(base, out)
        (out / "extraction.json").write_text(text)
        cases.append({"name": name, "argv": ["extract", str(log), "--spec", str(spec), "-o", str(out), "--resume",
                                             "--jobs", "1"], "state": str(out / "extraction.json")})
    for r in run_cases(cases, tmp_path):
        name = r["name"]
        assert r["code"] == 2 and not r["traceback"] and not r["hang"], (name, r)
        assert "Traceback" not in r["stderr"] and r["state"] in r["stderr"], (name, r["stderr"])
        assert expected[name] in r["stderr"] and "drop --resume" in r["stderr"], (name, r["stderr"])


def _edited(state: dict, edit) -> dict:
    state = json.loads(json.dumps(state))
    edit(state)
    return state


def test_the_named_journal_tamperings_are_one_clear_error_each(tmp_path):
    base = make_journal(tmp_path)
    named = {
        "an outcome nested 100k deep": ("UPDATE cases SET outcome=? WHERE case_id='c-000001'", (DEEP,),
                                        "cases[c-000001].outcome"),
        "meta seed not JSON": ("UPDATE meta SET value='{' WHERE key='seed'", (), "meta[seed]"),
        "text in reruns": ("UPDATE buckets SET reruns='x'", (), "buckets[B001].reruns"),
        "text in rerun_failures": ("UPDATE buckets SET rerun_failures='x'", (), "buckets[B001].rerun_failures"),
        "missing columns": ("ALTER TABLE buckets DROP COLUMN merged_into", (), "has no column 'merged_into'"),
        "text in blames.twins": ("UPDATE blames SET twins='x'", (), "blames[B001].twins"),
        "a verification's runs nested deep": ("UPDATE verifications SET runs=?", (DEEP,), "verifications[B001].runs"),
    }
    spec = tmp_path / "fuzz.yaml"
    cases = []
    for n, (name, (sql, args, field)) in enumerate(named.items()):
        for m, argv in enumerate((["fuzz", "--status", "-o"], ["report"],
                                  ["fuzz", "--resume", "--spec", str(spec), "--cases", "1", "--baseline", "1",
                                   "--no-minimise", "--horizon", "2", "-o"])):
            folder = tmp_path / f"named{n}-{m}"
            shutil.copytree(base, folder)
            db = sqlite3.connect(folder / "journal.sqlite")
            db.execute(sql, args)
            db.commit()
            db.close()
            cases.append({"name": name, "argv": [*argv, str(folder)], "state": str(folder / "journal.sqlite"),
                          "field": field})
    for case, r in zip(cases, run_cases(cases, tmp_path), strict=True):
        where = (r["name"], r["argv"][:2])
        assert r["code"] == 2 and not r["traceback"] and not r["hang"], (where, r)
        assert "Traceback" not in r["stderr"] and r["state"] in r["stderr"], (where, r["stderr"])
        assert case["field"] in r["stderr"], (where, r["stderr"])


def test_a_resumed_frame_is_judged_again_not_taken_from_the_state(tmp_path):
    """Verdicts edited in the state file (every frame 'not accepted', far off) change nothing: each resumed
    frame is stepped and compared with the recorded output again, so the suite is the run's."""
    spec, log, base = make_checkpoint(tmp_path)
    state = json.loads((base / "extraction.json").read_text())
    for item in state["decided"]:
        if "choice" in item:
            item.update(accepted=False, exact=False, comparison=dict(item["comparison"], distance=999.0))
    out = tmp_path / "edited"
    shutil.copytree(base, out)
    (out / "extraction.json").write_text(json.dumps(state))
    [result] = run_cases([{"name": "edited", "argv": ["extract", str(log), "--spec", str(spec), "-o", str(out),
                                                      "--resume", "--jobs", "1"], "state": ""}], tmp_path)
    assert result["code"] == 0, result
    assert len(json.loads((out / "deft.json").read_text())["frames"]) == 30  # every output, as in one go
