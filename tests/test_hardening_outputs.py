"""Output-side faults for every command that writes (issue 23, items 3 and 8), through the real CLI.

Each command is run as its own `python -m astaa_deft.cli` process against an
output place that cannot take its output: a regular file where a folder is
wanted (or a folder under a regular file), a read-only file system (a
read-only bind mount: the tests run as root, so permissions alone would not
refuse), a folder under /proc, and a file size limit of 0 (RLIMIT_FSIZE set
in the child, as `ulimit -f 0`: the tool must answer EFBIG, not die of
SIGXFSZ). Asserted for each: exit 4 (`output_place.EXIT_CANNOT_WRITE`), one
`astaa-deft: error:` line naming the path, no traceback — and, where the
command has long work to do, that the refusal came before it.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

import pytest

from astaa_deft.io.output_place import EXIT_CANNOT_WRITE
from toy_run import toy_log

ROOT = Path(__file__).resolve().parent.parent
SUT = ROOT / "tests" / "sut"
DEMO_SPEC = ROOT / "astaa_deft" / "data" / "specs" / "demo_av.yaml"
ECHO_SPEC = SUT / "echo.yaml"
TIMEOUT_S = 120

TINY_SPEC = textwrap.dedent("""\
    name: tiny
    modules: [{name: a, command: "true"}]
    channels: [{name: data, key: t/data, producer: a, type: Sample}]
    types:
      Sample: {seq: uint64, value: float64}
    """)


def cli(*args: str, cwd: Path, fsize: int | None = None, env: dict[str, str] | None = None
        ) -> subprocess.CompletedProcess:
    """One `python -m astaa_deft.cli` process; ``fsize``: its RLIMIT_FSIZE in bytes (as `ulimit -f`)."""

    def limits() -> None:
        if fsize is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    full_env = dict(os.environ, **(env or {}))
    full_env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(SUT), str(ROOT), full_env.get("PYTHONPATH", "")]))
    return subprocess.run([sys.executable, "-m", "astaa_deft.cli", *args], capture_output=True, text=True,
                          cwd=cwd, env=full_env, preexec_fn=limits, timeout=TIMEOUT_S)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """A toy planner log and spec (DeFT's own crafted run), a tiny spec and a campaign journal."""
    sys.path.insert(0, str(Path(__file__).parent))
    try:
        from test_deft_oracle import crafted_log
    finally:
        sys.path.remove(str(Path(__file__).parent))
    from astaa_deft.orchestration.campaign.journal import Journal

    base = tmp_path_factory.mktemp("inputs")
    spec, log = crafted_log(base)
    tiny = base / "tiny.yaml"
    tiny.write_text(TINY_SPEC)
    campaign = base / "campaign"
    Journal(campaign).close()
    return {"toy_spec": spec, "toy_log": log, "tiny": tiny, "campaign": campaign}


# Each writing command: how to call it with its output at PLACE (a folder, or a file for `file` outputs).
COMMANDS: dict[str, tuple[str, Callable[[dict[str, Path], Path], list[str]]]] = {
    "generate": ("dir", lambda i, p: ["generate", "--spec", str(DEMO_SPEC), "--count", "3", "--seed", "1",
                                      "-o", str(p)]),
    "extract": ("dir", lambda i, p: ["extract", str(i["toy_log"]), "--spec", str(i["toy_spec"]), "-o", str(p)]),
    "minimise": ("dir", lambda i, p: ["minimise", str(i["toy_log"]), "--spec", str(i["toy_spec"]), "-o", str(p)]),
    "proxy --run-dir": ("dir", lambda i, p: ["proxy", "--spec", str(ECHO_SPEC), "--duration", "1",
                                             "--run-dir", str(p)]),
    "proxy --record": ("file", lambda i, p: ["proxy", "--spec", str(ECHO_SPEC), "--duration", "1",
                                             "--record", str(p)]),
    "fuzz": ("dir", lambda i, p: ["fuzz", "--spec", str(i["tiny"]), "--cases", "1", "-o", str(p)]),
    "demo": ("dir", lambda i, p: ["demo", "--out", str(p)]),
    "spec discover": ("file", lambda i, p: ["spec", "discover", "--connect", "tcp/127.0.0.1:9", "--seconds", "5",
                                            "-o", str(p)]),
}


def assert_refused(res: subprocess.CompletedProcess, names: str | Path) -> None:
    text = res.stdout + res.stderr
    assert res.returncode == EXIT_CANNOT_WRITE, f"exit {res.returncode}\n{text[-2000:]}"
    assert "Traceback" not in text, text[-3000:]
    errors = [line for line in res.stderr.splitlines() if line.startswith("astaa-deft: error:")]
    assert len(errors) == 1, res.stderr
    assert str(names) in errors[0], errors[0]


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_file_in_the_way(command, inputs, tmp_path):
    kind, argv = COMMANDS[command]
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder\n")
    place = blocker if kind == "dir" else blocker / "out.file"  # a file path whose folder is a file
    res = cli(*argv(inputs, place), cwd=tmp_path)
    assert_refused(res, place)
    assert blocker.read_text() == "not a folder\n"  # left as it was


@pytest.mark.parametrize("command", sorted(c for c, (kind, _) in COMMANDS.items() if kind == "dir"))
def test_a_folder_under_a_regular_file(command, inputs, tmp_path):
    _, argv = COMMANDS[command]
    (tmp_path / "a-file").write_text("x")
    place = tmp_path / "a-file" / "out"
    assert_refused(cli(*argv(inputs, place), cwd=tmp_path), place)


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_place_under_proc(command, inputs, tmp_path):
    kind, argv = COMMANDS[command]
    place = Path("/proc/astaa-deft-out") if kind == "dir" else Path("/proc/astaa-deft.out")
    assert_refused(cli(*argv(inputs, place), cwd=tmp_path), place)


@pytest.fixture
def read_only(tmp_path) -> Path:
    """A folder on a read-only bind mount of itself (root ignores permission bits, not a read-only mount)."""
    folder = tmp_path / "ro"
    (folder / "inside").mkdir(parents=True)
    mounted = subprocess.run(["mount", "--bind", str(folder), str(folder)], capture_output=True, text=True)
    if mounted.returncode != 0:
        pytest.skip(f"no bind mounts here: {mounted.stderr.strip()}")
    try:
        subprocess.run(["mount", "-o", "remount,bind,ro", str(folder)], check=True, capture_output=True)
        yield folder
    finally:
        subprocess.run(["umount", str(folder)], check=True, capture_output=True)


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_read_only_file_system(command, inputs, tmp_path, read_only):
    kind, argv = COMMANDS[command]
    place = read_only / "inside" / ("out" if kind == "dir" else "out.file")
    res = cli(*argv(inputs, place), cwd=tmp_path)
    assert_refused(res, place)
    assert "read-only" in res.stderr


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_file_size_limit_of_zero_is_efbig_not_sigxfsz(command, inputs, tmp_path):
    """`ulimit -f 0`: the default action of SIGXFSZ would kill the tool without a word; it says why instead."""
    kind, argv = COMMANDS[command]
    place = tmp_path / ("out" if kind == "dir" else "out.file")
    res = cli(*argv(inputs, place), cwd=tmp_path, fsize=0)
    assert_refused(res, place.parent if kind == "file" else place)
    assert "file size limit" in res.stderr and "ulimit -f" in res.stderr


def test_report_in_a_read_only_campaign_folder(inputs, tmp_path, read_only):
    import shutil

    subprocess.run(["umount", str(read_only)], check=True)
    campaign = read_only / "inside" / "campaign"
    shutil.copytree(inputs["campaign"], campaign)
    subprocess.run(["mount", "--bind", str(read_only), str(read_only)], check=True)
    subprocess.run(["mount", "-o", "remount,bind,ro", str(read_only)], check=True)
    res = cli("report", str(campaign), cwd=tmp_path)
    assert_refused(res, campaign)


def test_report_under_a_file_size_limit(inputs, tmp_path):
    import shutil

    campaign = tmp_path / "campaign"
    shutil.copytree(inputs["campaign"], campaign)
    res = cli("report", str(campaign), cwd=tmp_path, fsize=0)
    assert_refused(res, campaign)
    assert not (campaign / "report.html").exists()


@pytest.mark.parametrize("command", ["extract", "minimise"])
def test_the_output_is_checked_before_the_log_is_read(command, inputs, tmp_path):
    """`extract -o EXISTING_FILE` used to fail after the whole extraction: the place is refused first."""
    existing = tmp_path / "existing"
    existing.write_text("x")
    res = cli(command, str(tmp_path / "no-such.mcap"), "--spec", str(inputs["toy_spec"]), "-o", str(existing),
              cwd=tmp_path)
    assert_refused(res, existing)  # not the missing log's exit 2


def test_no_usable_temporary_directory_is_one_clear_error(inputs, tmp_path):
    """minimise needs a temporary directory. In a mount namespace of its own, every candidate tempfile tries
    (/tmp, /var/tmp, the current folder) is read-only while the output folder is fine: one clear error, exit 4."""
    out = Path("/dev/shm") / f"astaa-deft-test-{os.getpid()}-{tmp_path.name}"
    script = ("mount --bind /tmp /tmp && mount -o remount,bind,ro /tmp && "
              "mount --bind /var/tmp /var/tmp && mount -o remount,bind,ro /var/tmp && cd /proc && "
              'exec "$0" -m astaa_deft.cli minimise "$1" --spec "$2" -o "$3"')
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(SUT), str(ROOT)]))
    env.pop("TMPDIR", None)
    try:
        res = subprocess.run(["unshare", "-m", "sh", "-c", script, sys.executable, str(inputs["toy_log"]),
                              str(inputs["toy_spec"]), str(out)], capture_output=True, text=True, env=env,
                             timeout=TIMEOUT_S)
        if "unshare failed" in res.stderr or "mount:" in res.stderr:
            pytest.skip(f"no private mount namespace here: {res.stderr.strip()}")
        assert res.returncode == EXIT_CANNOT_WRITE, res.stdout + res.stderr
        assert "Traceback" not in res.stderr
        assert "no usable temporary directory" in res.stderr and "TMPDIR" in res.stderr
    finally:
        import shutil

        shutil.rmtree(out, ignore_errors=True)


def test_a_write_past_the_size_limit_mid_extraction_keeps_what_was_written(tmp_path):
    """The up-front check passes (room above 64 KiB); the suite's files then outgrow the limit while written.

    Exit 4 naming the file, and what was written stays readable: the frames
    log up to its last complete chunk, no half-written manifest.
    """
    from astaa_deft.io.log.reader import read_log

    spec, log = toy_log(tmp_path, cycles=600)
    full = tmp_path / "full"
    assert cli("extract", str(log), "--spec", str(spec), "-o", str(full), cwd=tmp_path).returncode == 0
    sizes = {p.name: p.stat().st_size for p in full.iterdir() if p.is_file()}
    limit = 96 * 1024
    assert max(sizes.values()) > limit, sizes  # the case really writes past the limit
    out = tmp_path / "limited"
    res = cli("extract", str(log), "--spec", str(spec), "-o", str(out), cwd=tmp_path, fsize=limit)
    assert res.returncode == EXIT_CANNOT_WRITE, res.stdout + res.stderr
    assert "Traceback" not in res.stderr
    assert "file size limit" in res.stderr and str(out) in res.stderr
    written = {p.name for p in out.iterdir()}
    assert not [n for n in written if n.endswith(".partial")], written
    if "deft.json" in written:
        json.loads((out / "deft.json").read_text())  # whole, never half
    if "frames.mcap" in written:
        read_log(out / "frames.mcap")  # readable up to its last complete chunk (must not raise)
