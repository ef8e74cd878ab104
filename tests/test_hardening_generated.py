"""Generated bad input through the real CLI entry point.

Four families — spec, policy, dictionary, damaged MCAP — each drawn by a
seeded generator (and, for specs, by hypothesis) from a valid input; and one
family per command that does long work on what it reads — extract, minimise,
generate, fuzz — given damaged logs, specs and dictionaries. Every
case runs `astaa_deft.cli.main` in a worker subprocess whose address space is
capped (RLIMIT_AS) and which stops each case after CASE_TIMEOUT_S seconds, so
a bomb or a hang is counted instead of taking the machine down. A few cases
per family also run through the installed `python -m astaa_deft.cli` as
separate processes.

Asserted for every case: no traceback, no hang, exit 2 for bad input (0 only
for an input that is still valid), and never a "Pass" on a damaged log;
`extract` may work from what a damaged log still holds, but says so (a
warning), and `minimise` never reports a reproduced failure from a log whose
run did not fail.
The default run draws ~40 cases per family; `pytest -m slow` draws ≥ 1,000
per family and prints the per-family figures.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import random
import resource
import signal
import subprocess
import sys
import textwrap
import time
import traceback
from collections import Counter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SUT = ROOT / "tests" / "sut"
DEMO_SPEC = ROOT / "astaa_deft" / "data" / "specs" / "demo_av.yaml"
DICTIONARY = ROOT / "astaa_deft" / "data" / "dictionaries" / "default.yaml"
POLICY = ROOT / "policies" / "examples" / "demo_huge_heading.xml"
CASE_TIMEOUT_S = 20.0
MEMORY_LIMIT = 3 << 30  # per worker process; a YAML or XML bomb would need far more

LOG_SPEC = textwrap.dedent("""\
    name: damaged
    modules: [{name: a, command: "true"}]
    channels: [{name: data, key: t/data, producer: a, type: Sample}]
    types:
      Sample: {seq: uint64, value: float64}
    invariants:
      - {name: value_small, kind: expression, channel: data, expr: "value < 10"}
    """)

YAML_HOSTILE = [
    "&a", "*a", "*zz", "!foo ", "!!python/object/apply:os.system ['true'] ", "<<: *a\n", "<<: {x: 1}\n",
    "[" * 300, "]" * 3, "{", "}", "\t", "9" * 5000, "-" + "9" * 400, "1e308", "1.0e+999", ".nan", "-.inf",
    "~", "null", "''", "? [a, b]\n: 1\n", "%YAML 1.1\n---\n", "---\n", "...\n", "\x00", "\ufeff", "- ", ": ",
    "a: &x [1, 2]\nb: &y [*x, *x, *x, *x, *x, *x, *x, *x]\nc: [*y, *y, *y, *y, *y, *y, *y, *y]\n",
    "'unterminated", '"\\xZZ"', "|\n  block\n", "key: value: other\n", "\r\n", "\u2028", "#", "@", "`",
]
XML_HOSTILE = [
    '<!DOCTYPE t [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">'
    '<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;"><!ENTITY d "&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;">]>',
    '<!DOCTYPE t [<!ENTITY xxe SYSTEM "file:///etc/passwd">]>', "&xxe;", "&d;", "&unknown;", "</", "<", ">",
    "&", "\x00", "NaN", "1e308", "-0", "9" * 5000, "<x>", "</x>", '<value type="float64">', "]]>", "<![CDATA[",
    "<?xml version='1.0'?>", "\ufeff", '"', "'", "=", "<!-- ", " -->",
]


# -- generators (pure, seeded) ----------------------------------------------------------------------
def mutate_text(text: str, rng: random.Random, hostile: list[str]) -> bytes:
    """1–3 edits of a valid file: flips, deletions, duplications, hostile tokens, cuts, non-UTF-8 bytes."""
    for _ in range(rng.randint(1, 3)):
        op = rng.randrange(8)
        lines = text.splitlines(keepends=True) or [""]
        if op == 0 and text:
            i = rng.randrange(len(text))
            text = text[:i] + chr(rng.randrange(32, 127)) + text[i + 1:]
        elif op == 1:
            del lines[rng.randrange(len(lines))]
            text = "".join(lines)
        elif op == 2:
            i = rng.randrange(len(lines))
            lines.insert(i, lines[i])
            text = "".join(lines)
        elif op in (3, 4, 5):
            i = rng.randrange(len(text) + 1)
            text = text[:i] + rng.choice(hostile) + text[i:]
        elif op == 6:
            text = text[:rng.randrange(len(text) + 1)]
        else:
            i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
            lines[i], lines[j] = lines[j], lines[i]
            text = "".join(lines)
    data = text.encode("utf-8", "surrogatepass")
    if rng.random() < 0.08 and data:
        i = rng.randrange(len(data))
        data = data[:i] + bytes([rng.choice([0x80, 0x9B, 0xC3, 0xFF])]) + data[i:]
    return data


def damaged_logs(full: bytes, boundaries: list[int], count: int, rng: random.Random) -> list[tuple[str, bytes]]:
    """Truncations at every record boundary (and one byte either side), then random cuts, bit flips,
    byte runs overwritten and zeroed ranges, up to `count` cases."""
    out: list[tuple[str, bytes]] = []
    for b in boundaries:
        for cut in (b - 1, b, b + 1):
            if 0 < cut < len(full):
                out.append((f"cut@{cut}", full[:cut]))
    rng.shuffle(out)
    out = out[:count // 3] if count < 3 * len(out) else out
    while len(out) < count:
        kind = rng.randrange(4)
        data = bytearray(full)
        if kind == 0:
            cut = rng.randrange(1, len(full))
            out.append((f"cut@{cut}", bytes(full[:cut])))
            continue
        if kind == 1:
            pos = rng.randrange(len(data))
            data[pos] ^= 1 << rng.randrange(8)
            name = f"flip@{pos}"
        elif kind == 2:
            pos = rng.randrange(len(data))
            n = rng.randint(2, 64)
            data[pos:pos + n] = bytes(rng.randrange(256) for _ in range(len(data[pos:pos + n])))
            name = f"noise@{pos}+{n}"
        else:
            pos = rng.randrange(len(data))
            n = rng.randint(1, 4000)
            data[pos:pos + n] = bytes(len(data[pos:pos + n]))
            name = f"zero@{pos}+{n}"
        if bytes(data) != full:
            out.append((name, bytes(data)))
    return out[:count]


def write_log(path: Path, spec_path: Path) -> list[int]:
    """A finished log of 3,000 messages in small chunks; returns the byte offsets of its records."""
    from astaa_deft.io.log.writer import LogWriter
    from astaa_deft.engine.spec.loader import load_spec

    spec = load_spec(spec_path)
    w = LogWriter(path, spec, chunk_size=2048)
    cid = w.bus_channel(spec.channel("data"))
    for i in range(3000):
        w.message(cid, 1_000_000_000 + i * 1_000_000, json.dumps({"seq": i, "value": 0.5}).encode())
    w.finish()
    return record_offsets(path)


def record_offsets(path: Path) -> list[int]:
    """The byte offsets of the records (chunks whole) of the MCAP file at ``path``."""
    from mcap.stream_reader import StreamReader

    offsets = []
    with open(path, "rb") as f:
        records = StreamReader(f, emit_chunks=True).records
        while True:
            offsets.append(f.tell())
            try:
                next(records)
            except StopIteration:
                break
    return sorted(set(offsets) - {0})


FUZZ_SPEC = textwrap.dedent("""\
    name: tiny
    modules: [{name: a, command: "true"}, {name: b, command: "true"}]
    channels: [{name: data, key: t/data, producer: a, consumers: [b], type: Sample}]
    types:
      Sample: {seq: uint64, value: float64}
    invariants:
      - {name: value_small, kind: expression, channel: data, expr: "value < 10"}
    """)
# A campaign's smallest form: one baseline run and one case, nothing re-run or minimised. Its modules exit at
# once, so a campaign that does start (the damage left the input valid) may end with a finding (exit 1).
FUZZ_ARGS = ["--cases", "1", "--baseline", "1", "--reruns", "0", "--no-minimise", "--horizon", "2", "--workers", "1"]


def log_and_damage(full_path: Path, count: int, rng: random.Random, work: Path) -> list[tuple[str, Path]]:
    """``count`` damaged copies of the log at ``full_path``, written under ``work``."""
    out = []
    for n, (name, data) in enumerate(damaged_logs(full_path.read_bytes(), record_offsets(full_path), count, rng)):
        path = work / f"case{n:05d}.mcap"
        path.write_bytes(data)
        out.append((name, path))
    return out


def damaged_texts(source: str, suffix: str, count: int, rng: random.Random, work: Path,
                  hostile: list[str] = YAML_HOSTILE) -> list[Path]:
    paths = []
    for n in range(count):
        path = work / f"text{n:05d}{suffix}"
        path.write_bytes(mutate_text(source, rng, hostile))
        paths.append(path)
    return paths


def command_cases(family: str, count: int, rng: random.Random, work: Path) -> list[dict]:
    """The per-command families: damaged logs, specs and dictionaries given to extract, minimise, generate, fuzz."""
    cases: list[dict] = []
    out = iter(work / f"out{n:05d}" for n in range(10**6))
    if family == "extract":
        from toy_run import toy_log

        spec, log = toy_log(work, cycles=40, chunk_size=1024)
        cases.append({"name": "intact", "argv": ["extract", str(log), "--spec", str(spec), "-o", str(next(out)),
                                                 "--jobs", "1"], "valid": True})
        logs = log_and_damage(log, (count - 1) * 2 // 3, rng, work)
        for name, path in logs:
            cases.append({"name": name, "argv": ["extract", str(path), "--spec", str(spec), "-o", str(next(out)),
                                                 "--jobs", "1"], "damaged": True})
        for n, path in enumerate(damaged_texts(spec.read_text(), ".yaml", count - 1 - len(logs), rng, work)):
            cases.append({"name": f"spec{n}", "argv": ["extract", str(log), "--spec", str(path),
                                                       "-o", str(next(out)), "--jobs", "1"]})
    elif family == "minimise":
        from test_minimise_units import RICH, intercepted_log

        log = work / "intercepted.mcap"
        intercepted_log(log, RICH)  # every mutation recorded, and no invariant broken: nothing to minimise
        cases.append({"name": "intact", "argv": ["minimise", str(log), "--spec", str(DEMO_SPEC), "-o",
                                                 str(next(out))], "no_failure": True})
        logs = log_and_damage(log, (count - 1) * 3 // 4, rng, work)
        for name, path in logs:
            cases.append({"name": name, "argv": ["minimise", str(path), "--spec", str(DEMO_SPEC), "-o",
                                                 str(next(out))], "damaged": True, "no_failure": True})
        for n, path in enumerate(damaged_texts(DEMO_SPEC.read_text(), ".yaml", count - 1 - len(logs), rng, work)):
            cases.append({"name": f"spec{n}", "argv": ["minimise", str(log), "--spec", str(path), "-o",
                                                       str(next(out))], "no_failure": True})
    elif family == "generate":
        for n, path in enumerate(damaged_texts(DEMO_SPEC.read_text(), ".yaml", count, rng, work)):
            cases.append({"name": f"spec{n}", "argv": ["generate", "--spec", str(path), "--count", "2",
                                                       "--seed", str(n), "-o", str(next(out))]})
    else:  # fuzz: damaged specs, and damaged dictionaries beside a good spec
        spec = work / "fuzz.yaml"
        spec.write_text(FUZZ_SPEC)
        half = count // 2
        for n, path in enumerate(damaged_texts(FUZZ_SPEC, ".yaml", half, rng, work)):
            cases.append({"name": f"spec{n}", "argv": ["fuzz", "--spec", str(path), "-o", str(next(out)),
                                                       *FUZZ_ARGS], "may_find": True})
        for n, path in enumerate(damaged_texts(DICTIONARY.read_text(), ".dict.yaml", count - half, rng, work)):
            cases.append({"name": f"dictionary{n}", "argv": ["fuzz", "--spec", str(spec), "--dictionary", str(path),
                                                             "-o", str(next(out)), *FUZZ_ARGS], "may_find": True})
    return cases


def build_cases(family: str, count: int, seed: int, work: Path) -> list[dict]:
    """Each case: the file written under `work` and the CLI arguments that read it."""
    rng = random.Random(f"{family}-{seed}")
    work.mkdir(parents=True, exist_ok=True)
    if family in COMMAND_FAMILIES:
        return command_cases(family, count, rng, work)
    cases = []
    if family == "mcap":
        spec_path = work / "log_spec.yaml"
        spec_path.write_text(LOG_SPEC)
        full_path = work / "full.mcap"
        boundaries = write_log(full_path, spec_path)
        cases.append({"name": "intact", "argv": ["check", str(full_path), "--spec", str(spec_path)],
                      "valid": True})
        for n, (name, data) in enumerate(damaged_logs(full_path.read_bytes(), boundaries, count - 1, rng)):
            path = work / f"case{n:05d}.mcap"
            path.write_bytes(data)
            command = ["check", str(path), "--spec", str(spec_path)] if n % 5 else ["log", "info", str(path)]
            cases.append({"name": name, "argv": command, "damaged": True})
        return cases
    source = {"spec": DEMO_SPEC, "dictionary": DICTIONARY, "policy": POLICY}[family]
    text = source.read_text()
    hostile = XML_HOSTILE if family == "policy" else YAML_HOSTILE
    for n in range(count):
        data = mutate_text(text, rng, hostile)
        path = work / f"case{n:05d}{source.suffix}"
        path.write_bytes(data)
        if family == "spec":
            argv = ["spec", "check", str(path)]
        elif family == "policy":
            argv = ["policy", "check", str(path), "--spec", str(DEMO_SPEC)]
        else:
            argv = ["generate", "--spec", str(DEMO_SPEC), "--dictionary", str(path), "--count", "2",
                    "--seed", str(n), "-o", str(work / "out")]
        cases.append({"name": f"{family}{n}", "argv": argv})
    return cases


# -- the worker: many cases in one capped process ---------------------------------------------------
class _Hang(BaseException):
    pass


def _on_alarm(signum, frame):
    raise _Hang()


def run_worker(cases_file: Path, results_file: Path) -> None:
    from astaa_deft.cli import main

    signal.signal(signal.SIGALRM, _on_alarm)
    results = []
    for case in json.loads(cases_file.read_text()):
        out, err = io.StringIO(), io.StringIO()
        started = time.monotonic()
        outcome = {"name": case["name"], "argv": case["argv"], "code": None, "traceback": None, "hang": False}
        signal.setitimer(signal.ITIMER_REAL, CASE_TIMEOUT_S)
        try:
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                outcome["code"] = main(case["argv"])
        except SystemExit as exc:  # argparse usage errors
            outcome["code"] = exc.code if isinstance(exc.code, int) else 2
        except _Hang:
            outcome["hang"] = True
        except BaseException:  # noqa: BLE001 — anything escaping main() is the bug being counted
            outcome["traceback"] = traceback.format_exc()[-1500:]
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
        outcome.update(stdout=out.getvalue()[-3000:], stderr=err.getvalue()[-3000:],
                       seconds=round(time.monotonic() - started, 3), valid=case.get("valid", False),
                       damaged=case.get("damaged", False), no_failure=case.get("no_failure", False),
                       may_find=case.get("may_find", False))
        results.append(outcome)
    results_file.write_text(json.dumps(results))


def _limits() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


def _env() -> dict[str, str]:
    """The toy planner's replay factory (tests/sut) importable, as the spec beside the DeFT tests needs."""
    return dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(SUT), os.environ.get("PYTHONPATH")])))


def run_family(family: str, count: int, seed: int, work: Path) -> list[dict]:
    cases = build_cases(family, count, seed, work)
    cases_file, results_file = work / "cases.json", work / "results.json"
    cases_file.write_text(json.dumps(cases))
    proc = subprocess.run([sys.executable, __file__, "worker", str(cases_file), str(results_file)],
                          capture_output=True, text=True, preexec_fn=_limits, cwd=work, env=_env(),
                          timeout=CASE_TIMEOUT_S * len(cases) + 120)
    assert proc.returncode == 0, f"the worker died: {proc.stderr[-3000:]}"
    return json.loads(results_file.read_text())


# -- what must hold ---------------------------------------------------------------------------------
def problems_in(results: list[dict]) -> list[str]:
    bad = []
    for r in results:
        text = r["stdout"] + r["stderr"]
        where = f"{r['name']} ({' '.join(r['argv'][:2])})"
        if r["traceback"] or "Traceback" in text:
            bad.append(f"{where}: traceback\n{r['traceback'] or text}")
        elif r["hang"]:
            bad.append(f"{where}: no answer within {CASE_TIMEOUT_S} s")
        elif r.get("no_failure") and r["code"] != 2:
            bad.append(f"{where}: minimise of a run that did not fail exited {r['code']} (2 expected)\n{text[-800:]}")
        elif r["damaged"]:
            if "verdict: Pass" in r["stdout"] or (r["argv"][0] == "check" and r["code"] != 2):
                bad.append(f"{where}: a damaged log was judged (exit {r['code']})\n{text[-800:]}")
            elif r["argv"][0] == "log" and "finished cleanly: yes" in r["stdout"]:
                bad.append(f"{where}: log info calls a damaged log clean\n{text[-800:]}")
            elif r["code"] not in (0, 1, 2):
                bad.append(f"{where}: exit {r['code']} for a damaged log\n{text[-800:]}")
            elif r["argv"][0] == "extract" and r["code"] != 2 and "warning:" not in text:
                bad.append(f"{where}: extract worked from a damaged log without a word\n{text[-800:]}")
        elif r["valid"]:
            if r["code"] != 0:
                bad.append(f"{where}: a valid input was refused (exit {r['code']})\n{text[-800:]}")
        elif r["code"] not in ((0, 1, 2) if r.get("may_find") else (0, 2)):
            bad.append(f"{where}: exit {r['code']} for bad input\n{text[-800:]}")
        elif r["code"] == 2 and "astaa-deft: error:" not in r["stderr"] and "usage:" not in r["stderr"]:
            bad.append(f"{where}: exit 2 without a message\n{text[-800:]}")
    return bad


def figures(family: str, results: list[dict]) -> str:
    codes = Counter(r["code"] for r in results if not r["hang"] and not r["traceback"])
    slowest = max(r["seconds"] for r in results)
    return (f"{family}: {len(results)} cases, exit codes {dict(sorted(codes.items(), key=str))}, "
            f"tracebacks {sum(bool(r['traceback']) for r in results)}, hangs {sum(r['hang'] for r in results)}, "
            f"slowest {slowest:.2f} s")


COMMAND_FAMILIES = ["extract", "minimise", "generate", "fuzz"]
FAMILIES = ["spec", "policy", "dictionary", "mcap", *COMMAND_FAMILIES]


@pytest.mark.parametrize("family", FAMILIES)
def test_generated_bad_input_short(family, tmp_path):
    results = run_family(family, 40, seed=20261123, work=tmp_path)
    print(figures(family, results))
    assert not problems_in(results), "\n\n".join(problems_in(results)[:5])
    # The generator really makes bad input: refused, or (a damaged log extract still works from) warned about.
    assert sum(r["code"] == 2 or (r["damaged"] and "warning:" in r["stdout"] + r["stderr"])
               for r in results) >= len(results) // 2


@pytest.mark.slow
@pytest.mark.timeout(4 * 3600)  # 1,000 cases take longer than the suite's 300 s; each case has its own timeout
@pytest.mark.parametrize("family", FAMILIES)
def test_generated_bad_input_full(family, tmp_path):
    results = run_family(family, 1000, seed=1, work=tmp_path)
    report = figures(family, results)
    print(report)
    figures_file = os.environ.get("ASTAA_DEFT_FIGURES")
    if figures_file:
        with open(figures_file, "a") as f:
            f.write(report + "\n")
    assert len(results) >= 1000
    assert not problems_in(results), "\n\n".join(problems_in(results)[:5])


def installed_command_cases(per_family: int, tmp_path: Path) -> None:
    """The same checks on separate `python -m astaa_deft.cli` processes (the entry point users run): the first
    ``per_family`` cases of every family (for extract and minimise: the intact log, then damaged ones)."""
    checked = 0
    for family in FAMILIES:
        cases = build_cases(family, 6, seed=7, work=tmp_path / family)
        for case in cases[:per_family]:
            res = subprocess.run([sys.executable, "-m", "astaa_deft.cli", *case["argv"]], capture_output=True,
                                 text=True, timeout=60, preexec_fn=_limits, cwd=tmp_path, env=_env())
            r = dict(case, code=res.returncode, stdout=res.stdout, stderr=res.stderr, traceback=None, hang=False,
                     valid=case.get("valid", False), damaged=case.get("damaged", False),
                     no_failure=case.get("no_failure", False), may_find=case.get("may_find", False))
            assert not problems_in([r]), problems_in([r])
            checked += 1
    assert checked == per_family * len(FAMILIES)


def test_a_few_cases_through_the_installed_command(tmp_path):
    """Two cases of every family through the entry point users run (each a process of its own)."""
    installed_command_cases(2, tmp_path)


@pytest.mark.slow
def test_more_cases_through_the_installed_command(tmp_path):
    """Four cases of every family through the entry point users run."""
    installed_command_cases(4, tmp_path)


def test_extract_of_a_log_cut_before_its_channels_is_one_clear_error(tmp_path):
    """Found by the extract family at 1,000: the replay process's InputError came back as a RuntimeError."""
    from toy_run import toy_log

    spec, log = toy_log(tmp_path, cycles=10, chunk_size=1024)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(log.read_bytes()[:50])  # the header only: no channel at all
    res = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "extract", str(cut), "--spec", str(spec),
                          "-o", str(tmp_path / "out")], capture_output=True, text=True, timeout=120, env=_env())
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    assert f"{cut}: the log has no channel 'pose'" in res.stderr


def test_a_replay_arg_the_factory_does_not_take_is_one_clear_error(tmp_path):
    """Found by the extract family at 1,000: a misspelt replay arg reached the factory as a TypeError."""
    from toy_run import toy_log

    spec, log = toy_log(tmp_path, cycles=10)
    spec.write_text(spec.read_text().replace('args: {stop: "{stop}"', 'args: {stop-: "{stop}"'))
    res = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "extract", str(log), "--spec", str(spec),
                          "-o", str(tmp_path / "out")], capture_output=True, text=True, timeout=120, env=_env())
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    assert "planner.replay: replay factory 'toy_planner:ToyPlanner' does not take these args" in res.stderr
    assert "stop-" in res.stderr


def test_hypothesis_specs_never_traceback(tmp_path):
    """Structured YAML drawn by hypothesis in place of spec sections: each is loaded or refused with exit 2."""
    import hypothesis
    import yaml
    from hypothesis import strategies as st

    from astaa_deft.cli import main

    scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**30, 10**30),
                        st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12))
    values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                           st.dictionaries(st.text(max_size=8), inner, max_size=4)),
                          max_leaves=20)
    base = yaml.safe_load(DEMO_SPEC.read_text())
    sections = sorted(base)
    counter = iter(range(10**6))

    @hypothesis.settings(max_examples=int(os.environ.get("ASTAA_DEFT_HYPOTHESIS_EXAMPLES", "60")), deadline=None,
                         derandomize=True, database=None)
    @hypothesis.given(section=st.sampled_from(sections), value=values)
    def check(section, value):
        doc = dict(base, **{section: value})
        path = tmp_path / f"h{next(counter)}.yaml"
        path.write_text(yaml.safe_dump(doc, allow_unicode=True))
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()) as err:
            code = main(["spec", "check", str(path)])
        assert code in (0, 2), err.getvalue()
        if code == 2:
            assert "astaa-deft: error:" in err.getvalue()

    check()


if __name__ == "__main__" and len(sys.argv) == 4 and sys.argv[1] == "worker":
    run_worker(Path(sys.argv[2]), Path(sys.argv[3]))
