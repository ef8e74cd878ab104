"""Outputs are never written through a link: one rule, in io/output_place.py, for every writer.

A file written in one go is a new file renamed into place (a link at the target is replaced, never followed);
a file written as it goes (a log, a module's output) is opened as a new file, and a symbolic link at its path
is refused with exit 4; a journal that is a link is refused the same way. Real files, real commands.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from astaa_deft.io.output_place import OutputError, open_new, write_atomic

CLI = [sys.executable, "-c", "import sys; from astaa_deft.cli import main; sys.exit(main())"]
SPEC = """\
name: links
modules: [{name: a, command: ["%s", "-c", "import time; time.sleep(30)"]}]
channels: [{name: data, key: t/data, producer: a, type: Sample}]
types:
  Sample: {seq: uint64}
"""


def test_proxy_record_to_a_symlink_is_refused_and_the_target_untouched(tmp_path):
    target = tmp_path / "elsewhere.txt"
    target.write_text("precious")
    link = tmp_path / "run.mcap"
    link.symlink_to(target)
    spec = tmp_path / "sut.yaml"
    spec.write_text(SPEC % sys.executable)
    res = subprocess.run([*CLI, "proxy", "--spec", str(spec), "--record", str(link), "--duration", "1"],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 4, res.stdout + res.stderr
    assert "is a symbolic link: the tool never writes through a link" in res.stderr and "--record" in res.stderr
    assert "Traceback" not in res.stderr
    assert target.read_text() == "precious" and link.is_symlink()


def test_write_atomic_replaces_a_link_instead_of_writing_through_it(tmp_path):
    target = tmp_path / "elsewhere.txt"
    target.write_text("precious")
    out = tmp_path / "report.html"
    out.symlink_to(target)
    write_atomic(out, "new")
    assert not out.is_symlink() and out.read_text() == "new"
    assert target.read_text() == "precious"
    assert [p.name for p in tmp_path.iterdir() if "partial" in p.name] == []


def test_a_link_planted_at_the_old_temporary_name_is_not_followed(tmp_path):
    target = tmp_path / "elsewhere.txt"
    target.write_text("precious")
    (tmp_path / ".out.json.partial").symlink_to(target)  # the name write_atomic used before
    write_atomic(tmp_path / "out.json", "{}")
    assert (tmp_path / "out.json").read_text() == "{}" and target.read_text() == "precious"


def test_open_new_refuses_a_symlink_and_keeps_a_hard_link_elsewhere_intact(tmp_path):
    target = tmp_path / "elsewhere.txt"
    target.write_text("precious")
    link = tmp_path / "log.txt"
    link.symlink_to(target)
    with pytest.raises(OutputError) as caught:
        open_new(link, "--record")
    assert caught.value.exit_code == 4 and "symbolic link" in str(caught.value)
    hard = tmp_path / "hard.txt"
    os.link(target, hard)
    with open_new(hard) as f:
        f.write(b"new")
    assert hard.read_bytes() == b"new" and target.read_text() == "precious"


def test_open_new_never_removes_a_device(tmp_path):
    link_free = Path("/dev/null")
    with pytest.raises(OutputError):
        open_new(link_free)
    assert link_free.exists()


def test_a_journal_that_is_a_link_is_refused(tmp_path):
    elsewhere = tmp_path / "elsewhere.sqlite"
    elsewhere.write_bytes(b"")
    campaign = tmp_path / "campaign"
    campaign.mkdir()
    (campaign / "journal.sqlite").symlink_to(elsewhere)
    for argv in (["report", str(campaign)], ["fuzz", "--status", "-o", str(campaign)]):
        res = subprocess.run([*CLI, *argv], capture_output=True, text=True, timeout=120)
        assert res.returncode == 4, res.stdout + res.stderr
        assert "symbolic link" in res.stderr and "Traceback" not in res.stderr
    assert elsewhere.read_bytes() == b""


def test_an_interrupted_extractions_state_replaces_a_link(tmp_path):
    """extraction.json is written whole by rename: a link there is replaced, its target untouched."""
    sys.path[:0] = [str(Path(__file__).parent), str(Path(__file__).parent / "sut")]
    try:
        from toy_run import toy_log

        from astaa_deft.analysis.deft.workflow import ExtractOptions, extract_module_tests

        spec, log = toy_log(tmp_path, cycles=12)
        out = tmp_path / "out"
        out.mkdir()
        target = tmp_path / "elsewhere.json"
        target.write_text("precious")
        (out / "extraction.json").symlink_to(target)

        def stop(done: int, total: int) -> None:
            if done == 5:
                raise KeyboardInterrupt

        report = extract_module_tests(log, spec, out, ExtractOptions(jobs=1), progress=stop)
    finally:
        del sys.path[:2]
    assert report.interrupted
    assert not (out / "extraction.json").is_symlink() and target.read_text() == "precious"
