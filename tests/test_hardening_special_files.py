"""Special files given where a command reads a file: a FIFO with no writer, /dev/zero.

Every command that reads a spec, a test case, a dictionary, a log or a
campaign journal is run as its own `python -m astaa_deft.cli` process with
that input replaced by a special file. A FIFO blocks its reader until a
writer comes (none will), /dev/zero never ends: reading either as a file
is a hang or a memory blow-up. Asserted: exit 2, one `astaa-deft: error:`
line naming the file, no traceback, an answer within CASE_TIMEOUT_S. The
default run gives each kind of input to one reader; `pytest -m slow` to
every reader.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

from toy_run import toy_log

ROOT = Path(__file__).resolve().parent.parent
SUT = ROOT / "tests" / "sut"
DEMO_SPEC = ROOT / "astaa_deft" / "data" / "specs" / "demo_av.yaml"
ECHO_SPEC = SUT / "echo.yaml"
POLICY = ROOT / "policies" / "examples" / "demo_huge_heading.xml"
CASE_TIMEOUT_S = 10.0  # a refusal is immediate; a reader blocked on a FIFO never answers
MEMORY_LIMIT = 3 << 30  # /dev/zero read whole would take all the memory there is


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("special")
    spec, log = toy_log(base, cycles=10)
    from astaa_deft.orchestration.journal.journal import FILE_NAME

    campaign = base / "campaign"
    campaign.mkdir()
    os.mkfifo(campaign / FILE_NAME)  # the journal itself a FIFO
    fifo = base / "fifo"
    os.mkfifo(fifo)
    return {"toy_spec": spec, "toy_log": log, "fifo": fifo, "fifo_campaign": campaign}


# Each reader: the command line with the special file S in the place of one input (O: a fresh output place).
Reader = Callable[[dict[str, Path], str, Path], list[str]]
READERS: dict[str, Reader] = {
    "spec check": lambda i, s, o: ["spec", "check", s],
    "proxy --spec": lambda i, s, o: ["proxy", "--spec", s, "--duration", "1", "--run-dir", str(o)],
    "generate --spec": lambda i, s, o: ["generate", "--spec", s, "--count", "1", "--seed", "1", "-o", str(o)],
    "extract --spec": lambda i, s, o: ["extract", str(i["toy_log"]), "--spec", s, "-o", str(o)],
    "minimise --spec": lambda i, s, o: ["minimise", str(i["toy_log"]), "--spec", s, "-o", str(o)],
    "fuzz --spec": lambda i, s, o: ["fuzz", "--spec", s, "--cases", "1", "-o", str(o)],
    "check --spec": lambda i, s, o: ["check", str(i["toy_log"]), "--spec", s],
    "policy check": lambda i, s, o: ["policy", "check", s],
    "proxy --policy": lambda i, s, o: ["proxy", "--spec", str(ECHO_SPEC), "--policy", s, "--duration", "1",
                                       "--run-dir", str(o)],
    "generate --dictionary": lambda i, s, o: ["generate", "--spec", str(DEMO_SPEC), "--dictionary", s,
                                              "--count", "1", "--seed", "1", "-o", str(o)],
    "policy check --dictionary": lambda i, s, o: ["policy", "check", str(POLICY), "--spec", str(DEMO_SPEC),
                                                  "--dictionary", s],
    "proxy --dictionary": lambda i, s, o: ["proxy", "--spec", str(DEMO_SPEC), "--policy", str(POLICY),
                                           "--dictionary", s, "--duration", "1", "--run-dir", str(o)],
    "fuzz --dictionary": lambda i, s, o: ["fuzz", "--spec", str(DEMO_SPEC), "--dictionary", s, "--cases", "1",
                                          "-o", str(o)],
    "log info": lambda i, s, o: ["log", "info", s],
    "check LOG": lambda i, s, o: ["check", s, "--spec", str(i["toy_spec"])],
    "extract LOG": lambda i, s, o: ["extract", s, "--spec", str(i["toy_spec"]), "-o", str(o)],
    "minimise LOG": lambda i, s, o: ["minimise", s, "--spec", str(i["toy_spec"]), "-o", str(o)],
}

# The default run gives each kind of input once (its first reader); `-m slow` gives every reader.
DEFAULT_READERS = {"spec check", "policy check", "generate --dictionary", "log info"}

def cases() -> list:
    out = []
    for name in READERS:
        for kind in ("fifo", "/dev/zero"):
            marks = [] if name in DEFAULT_READERS else [pytest.mark.slow]
            out.append(pytest.param(name, kind, marks=marks, id=f"{name}-{kind}"))
    out.append(pytest.param("report", "fifo", id="report-fifo journal"))
    return out


def _limits() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


@pytest.mark.parametrize(("reader", "kind"), cases())
def test_a_special_file_is_refused_promptly(reader, kind, inputs, tmp_path):
    if reader == "report":
        special, argv = inputs["fifo_campaign"], ["report", str(inputs["fifo_campaign"])]
    else:
        special = inputs["fifo"] if kind == "fifo" else Path("/dev/zero")
        argv = READERS[reader](inputs, str(special), tmp_path / "out")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(SUT), str(ROOT),
                                                                      os.environ.get("PYTHONPATH")])))
    proc = subprocess.Popen([sys.executable, "-m", "astaa_deft.cli", *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=env, preexec_fn=_limits,
                            start_new_session=True)
    try:
        out, err = proc.communicate(timeout=CASE_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, 9)  # the group this test started: the tool and anything it launched
        proc.communicate()
        pytest.fail(f"{reader} on a {kind}: no answer within {CASE_TIMEOUT_S:g} s")
    assert "Traceback" not in out + err, (out + err)[-3000:]
    assert proc.returncode == 2, f"exit {proc.returncode}\n{(out + err)[-2000:]}"
    errors = [line for line in err.splitlines() if line.startswith("astaa-deft: error:")]
    assert errors and str(special) in errors[0], err
