"""Output-side faults for every command that writes, through the real CLI.

Each command is run as its own `python -m astaa_deft.cli` process against an
output place that cannot take its output: a regular file where a folder is
wanted (or a folder under a regular file), a read-only file system (a
read-only bind mount in a mount namespace of the command's own — root's, or
an unprivileged user's mapped to root in a user namespace of its own: no
mount privilege needed, nothing left mounted, and root ignores permission
bits, not a read-only mount), a folder under /proc, and a file size limit of 0 (RLIMIT_FSIZE set
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


# A mount namespace of its own: root's, or (without mount privilege) in a user namespace mapping the user to root.
UNSHARE = ["unshare", "--mount"] if os.geteuid() == 0 else ["unshare", "--user", "--map-root-user", "--mount"]
# In that namespace, each folder given before `--` becomes a read-only bind mount of itself; then the command.
READ_ONLY_THEN = ('while [ "$1" != -- ]; do mount --bind "$1" "$1" && mount -o remount,bind,ro "$1" || exit 97; '
                  'shift; done; shift; exec "$@"')


def private_mounts_unavailable() -> str:
    """Why no command here can get a mount namespace with a read-only bind mount ('' when one can)."""
    probe = subprocess.run([*UNSHARE, "sh", "-c", READ_ONLY_THEN, "sh", "/tmp", "--", "true"], capture_output=True,
                           text=True, timeout=30)
    return "" if probe.returncode == 0 else f"{' '.join(UNSHARE)}: {probe.stderr.strip() or probe.returncode}"


def cli(*args: str, cwd: Path, fsize: int | None = None, env: dict[str, str] | None = None,
        read_only: tuple[Path, ...] = ()) -> subprocess.CompletedProcess:
    """One `python -m astaa_deft.cli` process; ``fsize``: its RLIMIT_FSIZE in bytes (as `ulimit -f`);
    ``env``: its whole environment (default: this one's); ``read_only``: folders it sees as read-only bind
    mounts, in a mount namespace of its own."""

    def limits() -> None:
        if fsize is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    full_env = dict(os.environ if env is None else env)
    full_env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(SUT), str(ROOT), full_env.get("PYTHONPATH", "")]))
    command = [sys.executable, "-m", "astaa_deft.cli", *args]
    if read_only:
        command = [*UNSHARE, "sh", "-c", READ_ONLY_THEN, "sh", *map(str, read_only), "--", *command]
    res = subprocess.run(command, capture_output=True, text=True, cwd=cwd, env=full_env, preexec_fn=limits,
                         timeout=TIMEOUT_S)
    assert res.returncode != 97, f"the read-only bind mount was not made: {res.stderr}"
    return res


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """A toy planner log and spec (DeFT's own crafted run), a tiny spec and a campaign journal."""
    sys.path.insert(0, str(Path(__file__).parent))
    try:
        from test_deft_oracle import crafted_log
    finally:
        sys.path.remove(str(Path(__file__).parent))
    from astaa_deft.orchestration.journal.journal import Journal

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
    """A folder the command sees read-only (``cli(..., read_only=(folder,))``), with a folder inside it."""
    unavailable = private_mounts_unavailable()
    if unavailable:  # a kernel or container without mount namespaces for this user: the check cannot be made here
        pytest.skip(f"no private mount namespace here ({unavailable})")
    folder = tmp_path / "ro"
    (folder / "inside").mkdir(parents=True)
    return folder


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_read_only_file_system(command, inputs, tmp_path, read_only):
    kind, argv = COMMANDS[command]
    place = read_only / "inside" / ("out" if kind == "dir" else "out.file")
    res = cli(*argv(inputs, place), cwd=tmp_path, read_only=(read_only,))
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

    campaign = read_only / "inside" / "campaign"
    shutil.copytree(inputs["campaign"], campaign)
    res = cli("report", str(campaign), cwd=tmp_path, read_only=(read_only,))
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
    unavailable = private_mounts_unavailable()
    if unavailable:  # a kernel or container without mount namespaces for this user: the check cannot be made here
        pytest.skip(f"no private mount namespace here ({unavailable})")
    out = Path("/dev/shm") / f"astaa-deft-test-{os.getpid()}-{tmp_path.name}"
    env = {k: v for k, v in os.environ.items() if k != "TMPDIR"}
    try:
        res = cli("minimise", str(inputs["toy_log"]), "--spec", str(inputs["toy_spec"]), "-o", str(out),
                  cwd=Path("/proc"), env=env, read_only=(Path("/tmp"), Path("/var/tmp")))
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
