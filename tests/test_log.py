"""Test logs: a log cut short (writer killed) is read up to the last complete
chunk with a warning, never an exception; garbage is a clear error."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from astaa_deft.errors import InputError
from astaa_deft.log.reader import read_log
from astaa_deft.log.writer import LogWriter
from astaa_deft.spec_loader import load_spec_text

SPEC = textwrap.dedent("""\
    name: t
    modules: [{name: a, command: "true"}]
    channels: [{name: data, key: t/data, producer: a, type: Sample}]
    types:
      Sample: {seq: uint64, value: float64}
    """)

N = 20_000


def write_killed_log(path: Path) -> None:
    """Write N messages, then die without finish() — as a recorder killed with -9."""
    code = textwrap.dedent(f"""
        import json, os
        from pathlib import Path
        from astaa_deft.log.writer import LogWriter
        from astaa_deft.spec_loader import load_spec_text
        spec = load_spec_text({SPEC!r})
        w = LogWriter(Path({str(path)!r}), spec)
        cid = w.bus_channel(spec.channel("data"))
        for i in range({N}):
            w.message(cid, 1_000_000_000 + i * 1000, json.dumps({{"seq": i, "value": i / 3}}).encode())
        w._stream.flush()
        os._exit(0)
        """)
    subprocess.run([sys.executable, "-c", code], check=True)


def test_killed_writer_log_is_read_to_the_last_chunk(tmp_path):
    path = tmp_path / "killed.mcap"
    write_killed_log(path)
    log = read_log(path)
    assert not log.finished
    assert log.warnings and "ends early" in log.warnings[0]
    seqs = [json.loads(m.data)["seq"] for m in log.on("t/data")]
    assert seqs == list(range(len(seqs)))  # a clean prefix, nothing invented
    print(f"recovered {len(seqs)} of {N} messages ({len(seqs) / N:.1%}) from a log whose writer was killed")
    assert len(seqs) / N >= 0.95


def test_log_cut_anywhere_never_raises(tmp_path):
    spec = load_spec_text(SPEC)
    full = tmp_path / "full.mcap"
    w = LogWriter(full, spec, chunk_size=4096)
    cid = w.bus_channel(spec.channel("data"))
    for i in range(2000):
        w.message(cid, i, json.dumps({"seq": i, "value": 0.5}).encode())
    w.finish()
    data = full.read_bytes()
    assert len(read_log(full).on("t/data")) == 2000 and read_log(full).finished
    previous = -1
    for cut in range(9, len(data), max(1, len(data) // 60)):
        part = tmp_path / "cut.mcap"
        part.write_bytes(data[:cut])
        log = read_log(part)
        n = len(log.on("t/data"))
        assert n >= previous  # more bytes never give fewer messages
        previous = n
        assert log.warnings


def test_not_an_mcap_file_is_a_clear_error(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"hello, this is not mcap at all")
    with pytest.raises(InputError, match="not an MCAP file"):
        read_log(bad)
    res = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "log", "info", str(bad)],
                         capture_output=True, text=True)
    assert res.returncode == 2 and "Traceback" not in res.stderr


def test_log_info_on_a_truncated_log(tmp_path):
    path = tmp_path / "killed.mcap"
    write_killed_log(path)
    res = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "log", "info", str(path)],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "finished cleanly: NO" in res.stdout
    assert "t/data" in res.stdout
    assert "warning" in res.stderr and "Traceback" not in res.stderr
