"""User regular expressions run in linear time: no pattern in a spec or a log hangs the tool.

A ReDoS family — catastrophic-backtracking patterns against the lines that make Python's ``re`` run for
hours — judged by ``check`` from a log whose embedded spec carries the pattern (a log is data: its author must
not be able to hang the tool that opens it); syntax RE2 does not run is one input error naming the file, the
place and the fix; and the live acceptance: ``proxy`` with ``(a+)+$`` watching a module that prints 5,000
``a`` and a ``!`` ends at its ``--duration``, and SIGTERM ends it at once. ``benchmarks/bench_redos.py``
prints the figures.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from astaa_deft.engine.spec.loader import load_spec_text
from astaa_deft.io.log.layout import SPEC_ATTACHMENT
from astaa_deft.model.errors import InputError
from astaa_deft.model.patterns import PatternError, compile_user_pattern

from monitor_helpers import HandMadeLog, load, spec_problems

# Catastrophic for a backtracking engine, each with the line that makes it so.
REDOS = [
    ("(a+)+$", "a" * 5000 + "!"),
    ("(a|a)*$", "a" * 5000 + "!"),
    ("(a|aa)+$", "a" * 5000 + "!"),
    ("(a*)*b", "a" * 5000),
    ("(.*a){20}", "a" * 5000),
    ("([a-z]+)*$", "a" * 5000 + "1"),
    ("(\\w+\\s?)*$", "word " * 1000 + "!"),
    ("^(([a-z])+.)+[A-Z]([a-z])+$", "a" * 5000),
    ("(x+x+)+y", "x" * 5000),
    ("(.*){1,1000}[bc]", "a" * 5000),
]
UNSUPPORTED = [  # (pattern, what the fix says)
    ("ERROR(?!S)", "lookarounds are not supported"),
    ("(?<=planner )failed", "lookarounds are not supported"),
    ("(a)\\1", "backreferences are not supported"),
    ("Error\\Z", "'\\z'"),
    ("a{1001}", "repetition counts go up to 1000"),
    ("([unclosed", "escape special characters"),
]


def redos_family(count: int) -> list[tuple[str, str]]:
    """``count`` (pattern, line) cases: each catastrophic pattern alone, inside an alternation, anchored."""
    shapes = ["{p}", "Traceback|{p}", "^(?:{p})", "(?:{p})|ERROR", "(?i){p}"]
    cases = [(shape.format(p=p), line) for p, line in REDOS for shape in shapes]
    return [cases[n % len(cases)] for n in range(count)]


def write_log(path: Path, pattern: str, line: str) -> None:
    spec_yaml = textwrap.dedent(f"""\
        name: patterns
        modules: [{{name: planning, command: "true"}}]
        channels: [{{name: plan, key: t/plan, producer: planning, type: Plan}}]
        types:
          Plan: {{seq: uint64}}
        invariants:
          - {{name: watched, kind: log, modules: [planning], pattern: {_quoted(pattern)}}}
          - {{name: errors, kind: exceptions, modules: [planning], pattern: {_quoted(pattern)}}}
        """)
    log = HandMadeLog(path, load_spec_text(spec_yaml, name="patterns.yaml"))
    log.writer.attachment(SPEC_ATTACHMENT, spec_yaml.encode(), "application/yaml")  # as the recorder does
    for n in range(3):
        log.event("module_log", 0.5 + n, module="planning", stream="output", line=line)
    log.event("run_stopping", 4.0)
    log.close()


def _quoted(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"


def check(log: Path, timeout: float = 60.0) -> tuple[subprocess.CompletedProcess, float]:
    started = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", "import sys; from astaa_deft.cli import main; sys.exit(main())",
                           "check", str(log)], capture_output=True, text=True, timeout=timeout)
    return proc, time.monotonic() - started


def short_form(line: str) -> str:
    """The catastrophic line at a dozen characters: Python's backtracking ``re`` still answers it at once."""
    return line[:12] + line[-1] if line[-1] != line[0] else line[:12]


def test_catastrophic_patterns_run_on_the_linear_engine_and_find_what_python_s_re_finds():
    """"At once" is the engine's guarantee, not a clock's: every pattern runs on RE2 (linear in the text: no
    backtracking), and on a short form of its line RE2 finds what Python's ``re`` finds, so the engine is a
    faithful one. The time on the full 5,000-character lines is printed, as a figure (bench_redos.py)."""
    import re

    import re2

    slowest = 0.0
    for pattern, line in redos_family(50):
        compiled = compile_user_pattern(pattern)
        assert isinstance(compiled._regexp, type(re2.compile(""))), pattern  # the linear engine, no fallback
        short = short_form(line)
        found, expected = compiled.search(short), re.search(pattern, short)
        assert (found and found.span()) == (expected and expected.span()), (pattern, short)
        started = time.perf_counter()
        compiled.search(line)
        slowest = max(slowest, time.perf_counter() - started)
    print(f"\nthe slowest of 50 catastrophic searches on 5,000 characters: {slowest * 1e3:.2f} ms")
    assert compile_user_pattern("(a+)+$").search("a" * 5000 + "!") is None
    assert compile_user_pattern("(a+)+$").search("a" * 5000) is not None


@pytest.mark.parametrize("size", [25, pytest.param(1000, marks=pytest.mark.slow)])
def test_redos_family_through_check(size, tmp_path):
    """Every case judged by `check` from the log alone; figures printed: cases, tracebacks, hangs."""
    cases = redos_family(size)
    tracebacks, hangs, slowest = 0, 0, 0.0
    # One process judges many logs (one `check` each) so the family stays fast; each case still has its own log.
    logs = []
    for n, (pattern, line) in enumerate(cases):
        path = tmp_path / f"case{n:05d}.mcap"
        write_log(path, pattern, line)
        logs.append(path)
    script = ("import sys, time, contextlib, io\nfrom astaa_deft.cli import main\nworst = 0.0\n"
              "for path in sys.argv[1:]:\n    t = time.monotonic()\n    out = io.StringIO()\n"
              "    with contextlib.redirect_stdout(out):\n        code = main(['check', path])\n"
              "    assert code in (0, 1), (path, code, out.getvalue())\n"
              "    worst = max(worst, time.monotonic() - t)\nprint('slowest', worst)\n")
    try:
        proc = subprocess.run([sys.executable, "-c", script, *map(str, logs)], capture_output=True, text=True,
                              timeout=60 + size)
    except subprocess.TimeoutExpired:
        hangs = 1
    else:
        tracebacks = proc.stderr.count("Traceback")
        assert proc.returncode == 0, proc.stderr[-2000:]
        slowest = float(proc.stdout.split()[-1])
    print(f"redos family: {len(cases)} cases, tracebacks {tracebacks}, hangs {hangs}, slowest check {slowest:.2f} s")
    assert (tracebacks, hangs) == (0, 0)


def test_check_of_a_log_carrying_a_catastrophic_pattern(tmp_path):
    log = tmp_path / "run.mcap"
    write_log(log, "(a+)+$", "a" * 5000 + "!")
    proc, seconds = check(log)
    print(f"check of a log with (a+)+$ and a 5,000-character line: {seconds:.2f} s")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stderr and "verdict: Pass" in proc.stdout
    write_log(log, "(a+)+$", "a" * 5000)  # the same pattern does match a line of a's only
    proc, _ = check(log)
    assert proc.returncode == 1 and "watched" in proc.stdout


@pytest.mark.parametrize("pattern, fix", UNSUPPORTED)
def test_syntax_the_engine_does_not_run_is_one_input_error(pattern, fix):
    with pytest.raises(PatternError) as caught:
        compile_user_pattern(pattern)
    assert fix in caught.value.fix
    for kind in ("log", "exceptions"):
        problems = spec_problems(f"- {{name: p, kind: {kind}, pattern: {_quoted(pattern)}}}")
        assert len(problems) == 1 and problems[0].file == "sut.yaml" and problems[0].line
        assert "'pattern'" in problems[0].message and fix in problems[0].fix


def test_ready_log_is_checked_by_the_same_engine():
    spec = textwrap.dedent("""\
        name: r
        modules: [{name: a, command: "true", ready: {log: "up(?=now)"}}]
        channels: [{name: c, key: t/c, producer: a, type: T}]
        types: {T: {seq: uint64}}
        """)
    with pytest.raises(InputError) as caught:
        load_spec_text(spec, name="r.yaml")
    problem = caught.value.problems[0]
    assert "'ready.log'" in problem.message and "lookarounds are not supported" in problem.fix
    assert problem.line == 2


def test_a_valid_pattern_still_works_as_before():
    spec = load('- {name: p, kind: log, pattern: "Traceback|ERROR \\\\d+"}')
    assert spec.invariants[0].pattern.search("ERROR 42") is not None


MODULE = """\
import time
print("ready", flush=True)
for _ in range(200):
    print("a" * 5000 + "!", flush=True)
    time.sleep(0.05)
time.sleep(60)
"""


def _proxy_spec(tmp_path: Path) -> Path:
    (tmp_path / "mod.py").write_text(MODULE)
    spec = tmp_path / "sut.yaml"
    spec.write_text(textwrap.dedent(f"""\
        name: redos
        modules:
          - {{name: planning, command: ["{sys.executable}", "{tmp_path / 'mod.py'}"], ready: {{log: "ready"}}}}
        channels:
          - {{name: plan, key: t/plan, producer: planning, type: Plan}}
        types:
          Plan: {{seq: uint64}}
        invariants:
          - {{name: errors, kind: exceptions, modules: [planning], pattern: "(a+)+$"}}
          - {{name: watched, kind: log, modules: [planning], pattern: "(a+)+$"}}
        """))
    return spec


def test_sigterm_ends_a_proxy_run_watching_a_catastrophic_pattern(tmp_path):
    """The run loop and the stop path never wait on a pattern: SIGTERM mid-run ends it, with its verdict."""
    spec = _proxy_spec(tmp_path)
    proc = subprocess.Popen([sys.executable, "-c", "import sys; from astaa_deft.cli import main; sys.exit(main())",
                             "proxy", "--spec", str(spec), "--record", str(tmp_path / "run.mcap"),
                             "--duration", "60", "--run-dir", str(tmp_path / "run")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        time.sleep(3.0)  # modules up, lines flowing
        sent = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=60)
        print(f"SIGTERM to exit: {time.monotonic() - sent:.2f} s")
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert "stopped (signal SIGTERM)" in out, out + err
    assert "Traceback" not in err
    assert "verdict: Pass" in out  # every line was judged: none matches (each ends in '!')


def test_the_stop_path_gives_up_on_a_stuck_monitor_and_withholds_the_verdict():
    """No user input makes a monitor stall any more (RE2), so a stuck one is stood in for: the stop path must
    not wait for it, and must not give a verdict on a run it did not judge to the end."""
    import threading

    from astaa_deft.engine.monitor.online import OnlineMonitors

    spec = load('- {name: p, kind: log, pattern: "ERROR"}')
    online = OnlineMonitors(spec, time.time_ns(), lambda v: None)
    stuck, entered = threading.Event(), threading.Event()

    def stuck_monitor(module: str, text: str, time_ns: int) -> list:
        entered.set()
        stuck.wait(120)
        return []

    online.set.on_log_line = stuck_monitor  # type: ignore[method-assign]
    online.log_line("planning", "a line", time.time_ns())
    assert entered.wait(10)
    try:
        assert online.finish(time.time_ns()) is None  # not fully judged: no verdict, and finish returned
    finally:
        stuck.set()
