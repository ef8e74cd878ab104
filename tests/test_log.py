"""Test logs: a log cut short (writer killed) is read up to the last complete
chunk with a warning, never an exception; garbage is a clear error."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from astaa_deft.model.errors import InputError
from astaa_deft.io.log.reader import read_log
from astaa_deft.io.log.writer import DEFAULT_CHUNK_SIZE, LogWriter
from astaa_deft.engine.spec.loader import load_spec_text

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
        from astaa_deft.io.log.writer import LogWriter
        from astaa_deft.engine.spec.loader import load_spec_text
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
    # What is lost is the open chunk only: the records of the messages after the last one read fit in one
    # chunk's 64 KiB (a chunk closes as soon as it outgrows it). A message record is its 31-byte header
    # (opcode, length, channel, sequence, two times) and its payload, as write_killed_log wrote them.
    lost = sum(31 + len(json.dumps({"seq": i, "value": i / 3}).encode()) for i in range(len(seqs), N))
    print(f"recovered {len(seqs)} of {N} messages; lost {N - len(seqs)} ({lost} bytes of records) "
          f"from a log whose writer was killed")
    assert 0 < lost <= DEFAULT_CHUNK_SIZE == 64 * 1024


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


@pytest.mark.parametrize("compression", ["zstd", ""])
def test_fast_mcap_writer_writes_the_bytes_of_mcaps_writer(tmp_path, compression):
    """log/mcap_writer.py replaces mcap's per-message path only: the file must be byte for byte the same."""
    from mcap.writer import CompressionType, Writer

    from astaa_deft.io.log.mcap_writer import McapWriter

    def scenario(writer) -> None:
        writer.start(profile="astaa-deft", library="same")
        schema = writer.register_schema("S", "jsonschema", b'{"type": "object"}')
        a = writer.register_channel("a", "json", schema, {"k": "v"})
        writer.add_attachment(create_time=5, log_time=6, name="spec.yaml", media_type="application/yaml",
                              data=b"name: x\n")
        writer.add_metadata("run", {"mode": "star"})
        for i in range(400):  # several chunks; log times out of order now and then; a channel added mid-chunk
            if i == 150:
                b = writer.register_channel("b", "cbor", 0, {})
            cid = b if i > 150 and i % 3 == 0 else a
            writer.add_message(cid, 1_000 + (i * 7919) % 997, bytes([i % 256]) * (i % 50),
                               publish_time=2_000 + i, sequence=i)
        writer.finish()

    ours, theirs = tmp_path / "ours.mcap", tmp_path / "theirs.mcap"
    with open(ours, "wb") as stream:
        scenario(McapWriter(stream, chunk_size=1024, compression=compression, enable_data_crcs=True))
    with open(theirs, "wb") as stream:
        scenario(Writer(stream, chunk_size=1024, enable_data_crcs=True,
                        compression=CompressionType.ZSTD if compression else CompressionType.NONE))
    assert ours.read_bytes() == theirs.read_bytes()


def write_finished_log(path: Path, count: int = 200) -> Path:
    spec = load_spec_text(SPEC)
    writer = LogWriter(path, spec)
    writer.attachment("spec.yaml", SPEC.encode())
    cid = writer.bus_channel(spec.channel("data"))
    for i in range(count):
        writer.message(cid, 1_000_000_000 + i * 1000, json.dumps({"seq": i, "value": 0.5}).encode())
    writer.finish()
    return path


@pytest.mark.parametrize("tail, says", [
    (None, "another MCAP log starts there"),  # the log written twice into one file
    (b"name: appended\nmodules: []\n", "data appended to the file"),  # YAML after the footer
    (b"\x00", "data appended to the file"),  # one stray byte
], ids=["log-twice", "yaml-appended", "one-byte"])
def test_bytes_after_the_log_end_are_damage(tmp_path, tail, says):
    one = write_finished_log(tmp_path / "one.mcap")
    assert read_log(one).intact
    path = tmp_path / "run.mcap"
    path.write_bytes(one.read_bytes() + (one.read_bytes() if tail is None else tail))
    log = read_log(path)
    assert log.finished and not log.intact and not log.truncated
    (damage,) = log.damage
    assert "follow the log's end" in damage and says in damage
    assert len(log.on("t/data")) == 200  # the first log is read, nothing invented from the rest

    info = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "log", "info", str(path)],
                          capture_output=True, text=True)
    assert info.returncode == 0, info.stderr
    assert "finished cleanly: NO" in info.stdout and "follow the log's end" in info.stderr

    check = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "check", str(path)],
                           capture_output=True, text=True)
    # As any damaged log with nothing broken in what was read: no Pass, the verdict withheld, exit 2.
    assert check.returncode == 2, check.stdout + check.stderr
    assert "verdict withheld" in check.stdout and "verdict: Pass" not in check.stdout
    assert "Traceback" not in check.stderr


def test_a_device_is_not_a_log(tmp_path):
    with pytest.raises(InputError, match="not a regular file"):
        read_log("/dev/zero")
    res = subprocess.run([sys.executable, "-m", "astaa_deft.cli", "log", "info", "/dev/zero"],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and "not a regular file" in res.stderr and "empty" not in res.stderr
