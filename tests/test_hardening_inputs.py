"""Input files and numeric options that used to block, exhaust memory or run unbounded.

Every case runs the real CLI entry point and must end in one clear message
(the file and the fix, or the option and its range), exit code 2, and no
traceback. The FIFO cases carry a timeout, so a regression to a blocking
``open()`` fails instead of hanging the run.
"""

from __future__ import annotations

import os
import socket
from pathlib import Path

import pytest

from astaa_deft.cli import main
from astaa_deft.cli.commands.demo import demo_spec_path
from astaa_deft.io.inputfile import DICTIONARY, POLICY, SPEC

ROOT = Path(__file__).resolve().parent.parent
POLICY_FILE = ROOT / "policies" / "examples" / "demo_huge_heading.xml"
DEMO_SPEC = str(demo_spec_path())


def run(capsys, *args: str) -> tuple[int, str]:
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out + out.err


def assert_refused(code: int, text: str, path: Path | str, says: str) -> None:
    assert "Traceback" not in text, text
    assert code == 2, text
    assert f"astaa-deft: error: {path}: {says}" in text, text


def _generate_with_dictionary(path: Path, out: Path) -> list[str]:
    return ["generate", "--spec", DEMO_SPEC, "--dictionary", str(path), "--count", "1", "--seed", "1",
            "-o", str(out)]


# ---------------------------------------------------------------- special files

@pytest.fixture
def fifo(tmp_path: Path) -> Path:
    path = tmp_path / "input.fifo"
    os.mkfifo(path)
    return path


@pytest.mark.timeout(30)
@pytest.mark.parametrize("reader", ["spec check", "policy check", "log info", "check", "dictionary"])
def test_a_fifo_is_refused_by_its_kind_without_blocking(reader, fifo, tmp_path, capsys):
    args = _generate_with_dictionary(fifo, tmp_path / "out") if reader == "dictionary" \
        else [*reader.split(), str(fifo)]
    code, text = run(capsys, *args)
    assert_refused(code, text, fifo, "is a named pipe (FIFO), not a regular file")


@pytest.mark.timeout(30)
def test_a_fifo_inside_a_policy_directory_is_refused_and_the_rest_checked(tmp_path, capsys):
    directory = tmp_path / "policies"
    directory.mkdir()
    os.mkfifo(directory / "a_pipe.xml")
    (directory / "b_ok.xml").write_bytes(POLICY_FILE.read_bytes())
    code, text = run(capsys, "policy", "check", str(directory))
    assert_refused(code, text, directory / "a_pipe.xml", "is a named pipe (FIFO)")
    assert f"{directory / 'b_ok.xml'}: ok" in text


@pytest.mark.timeout(30)
@pytest.mark.parametrize("reader", ["spec", "policy", "dictionary"])
def test_dev_zero_is_refused_before_any_read(reader, tmp_path, capsys):
    args = {"spec": ["spec", "check", "/dev/zero"], "policy": ["policy", "check", "/dev/zero"],
            "dictionary": _generate_with_dictionary(Path("/dev/zero"), tmp_path / "out")}[reader]
    code, text = run(capsys, *args)
    assert_refused(code, text, "/dev/zero", "is a character device, not a regular file")


def test_a_socket_is_refused(tmp_path, capsys):
    path = tmp_path / "s.sock"
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as server:
        server.bind(str(path))
        code, text = run(capsys, "spec", "check", str(path))
    assert_refused(code, text, path, "is a socket, not a regular file")


@pytest.mark.parametrize("kind,args", [
    (SPEC, lambda p, out: ["spec", "check", str(p)]),
    (POLICY, lambda p, out: ["policy", "check", str(p)]),
    (DICTIONARY, _generate_with_dictionary),
])
def test_a_file_over_its_kinds_cap_is_refused_by_its_size(kind, args, tmp_path, capsys):
    path = tmp_path / "huge"
    with open(path, "wb") as sparse:  # no disk used: the size alone must refuse it
        sparse.truncate(kind.max_bytes + 1)
    code, text = run(capsys, *args(path, tmp_path / "out"))
    assert_refused(code, text, path, f"the {kind.noun} is larger than {kind.cap_text}")


# ---------------------------------------------------------------- numeric options

BAD_OPTIONS = [
    (["generate", "--spec", DEMO_SPEC, "-o", "out", "--seed", "1", "--count", "1000000000000"], "--count"),
    (["generate", "--spec", DEMO_SPEC, "-o", "out", "--seed", "1", "--count", "0"], "--count"),
    (["generate", "--spec", DEMO_SPEC, "-o", "out", "--count", "1", "--seed", "-1"], "--seed"),
    (["generate", "--spec", DEMO_SPEC, "-o", "out", "--count", "1", "--seed", "1", "--duration", "inf"], "--duration"),
    (["extract", "log.mcap", "--spec", DEMO_SPEC, "-o", "out", "--threshold", "nan"], "--threshold"),
    (["extract", "log.mcap", "--spec", DEMO_SPEC, "-o", "out", "--threshold", "-1"], "--threshold"),
    (["extract", "log.mcap", "--spec", DEMO_SPEC, "-o", "out", "--jobs", "0"], "--jobs"),
    (["minimise", "log.mcap", "-o", "out", "--parallel", "100000"], "--parallel"),
    (["minimise", "log.mcap", "-o", "out", "--max-tests", "1e3"], "--max-tests"),
    (["fuzz", "-o", "out", "--cases", "99999999999"], "--cases"),
    (["fuzz", "-o", "out", "--workers", "0"], "--workers"),
    (["fuzz", "-o", "out", "--horizon", "1e308"], "--horizon"),
    (["fuzz", "-o", "out", "--budget", "100000h"], "--budget"),
    (["fuzz", "-o", "out", "--budget", "soon"], "--budget"),
    (["fuzz", "-o", "out", "--seed", str(2**63)], "--seed"),
    (["fuzz", "-o", "out", "--cluster", "local:100000"], "--cluster"),
    (["proxy", "--spec", DEMO_SPEC, "--duration", "nan"], "--duration"),
    (["spec", "discover", "--connect", "tcp/127.0.0.1:1", "-o", "out", "--domain", "1000"], "--domain"),
]


@pytest.mark.parametrize("args,option", BAD_OPTIONS, ids=[" ".join(a[:1] + [o, a[-1]]) for a, o in BAD_OPTIONS])
def test_out_of_range_option_is_a_usage_error(args, option, capsys):
    with pytest.raises(SystemExit) as exited:
        main(args)
    err = capsys.readouterr().err
    assert exited.value.code == 2, err
    assert "Traceback" not in err
    assert f"error: argument {option}: " in err, err


def test_the_ranges_are_said_in_help(capsys):
    with pytest.raises(SystemExit):
        main(["generate", "--help"])
    out = capsys.readouterr().out
    assert "[from 1 to 1,000,000]" in out
    with pytest.raises(SystemExit):
        main(["extract", "--help"])
    assert "[≥ 0 and ≤ 1000 m]" in capsys.readouterr().out
