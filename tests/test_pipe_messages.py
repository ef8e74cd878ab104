"""pipe_messages: frames round-trip, and a damaged channel is a clear error, never a hang or a short message."""

from __future__ import annotations

import os
import socket
import subprocess
import sys

import pytest

from astaa_deft.analysis.minimise.ddmin import Outcome, TestResult
from astaa_deft.analysis.minimise.replay_model import Job, ReplayAnswer, ReplaySetup
from astaa_deft.analysis.minimise.replay_pool import (AnswerMessage, BadInputMessage, JobMessage, ReadyMessage,
                                                      SetupMessage)
from astaa_deft.engine.bus import process_launch
from astaa_deft.io import pipe_messages
from astaa_deft.io.pipe_messages import (CBOR, HEADER_BYTES, JSON, FrameError, bytes_reader, fd_reader,
                                         read_frame)
from astaa_deft.model.errors import Problem


@pytest.mark.parametrize("encoding", [JSON, CBOR])
def test_each_replay_message_round_trips_in_either_body_encoding(encoding):
    messages = [SetupMessage(ReplaySetup(log_path="run.mcap", spec_path=None, invariant="planned_speed",
                                         module="planning", trust_log_spec=True)),
                JobMessage(Job(((1, (0, 2)), (4, None)), (3, 7))), JobMessage(Job(())),
                ReadyMessage(0.25), BadInputMessage((Problem("spec.yaml", 3, None, "bad", "fix it"),)),
                AnswerMessage(ReplayAnswer(TestResult(Outcome.UNRESOLVED, "hung", 0.5), 12))]
    kinds = (SetupMessage, JobMessage, ReadyMessage, BadInputMessage, AnswerMessage)
    stream = b"".join(pipe_messages.encode(m, encoding) for m in messages)
    read = bytes_reader(stream)
    assert [pipe_messages.receive(read, kinds, source="test") for _ in messages] == messages
    assert pipe_messages.receive(read, kinds, source="test") is None  # the clean end between frames


def test_a_frame_cut_short_is_an_error_naming_the_channel():
    whole = pipe_messages.encode(ReadyMessage(1.0))
    for cut in (1, HEADER_BYTES - 1, HEADER_BYTES, len(whole) - 1):
        with pytest.raises(FrameError, match="the replay pipe: the channel ended inside a frame"):
            read_frame(bytes_reader(whole[:cut]), source="the replay pipe")


def test_a_garbled_header_is_refused_before_anything_more_is_read():
    with pytest.raises(FrameError, match="garbled frame header"):
        read_frame(bytes_reader(b'{"kind": "ready"}\n'), source="x")


def test_a_frame_over_the_limit_is_refused_without_reading_its_body():
    head = pipe_messages.frame(b"")[:4] + (1 << 31).to_bytes(4, "big")
    calls = []

    def read(size: int) -> bytes:
        calls.append(size)
        return head if len(calls) == 1 else b""

    with pytest.raises(FrameError, match="over this channel's limit"):
        read_frame(read, source="x", max_bytes=1 << 20)
    assert calls == [HEADER_BYTES]


def test_an_unexpected_or_malformed_message_is_an_error():
    with pytest.raises(FrameError, match="unexpected message 'ready'"):
        pipe_messages.receive(bytes_reader(pipe_messages.encode(ReadyMessage(1.0))), (AnswerMessage,), source="x")
    bad = pipe_messages.frame(b'{"type": "ready", "baseline_seconds": "soon"}', JSON)
    with pytest.raises(FrameError, match="malformed 'ready' message"):
        pipe_messages.receive(bytes_reader(bad), (ReadyMessage,), source="x")
    with pytest.raises(FrameError, match="garbled message"):
        pipe_messages.receive(bytes_reader(pipe_messages.frame(b"{not json", JSON)), (ReadyMessage,), source="x")


def test_a_child_that_dies_mid_frame_does_not_hang_its_parent():
    read_fd, write_fd = os.pipe()
    whole = pipe_messages.encode(ReadyMessage(2.0))
    # A real child writes half a frame on the pipe and dies.
    child = process_launch.start([sys.executable, "-c", f"import os; os.write({write_fd}, {whole[:5]!r}); "
                                  "os._exit(9)"], pass_fds=(write_fd,))
    os.close(write_fd)
    try:
        assert child.wait(timeout=30) == 9
        with pytest.raises(FrameError, match="ended inside a frame's header"):
            read_frame(fd_reader(read_fd), source="the child")
    finally:
        os.close(read_fd)


def test_frames_cross_a_socket_and_a_pickle_frame_is_not_a_message():
    ours, theirs = socket.socketpair()
    with ours, theirs:
        pipe_messages.send_socket(ours, ReadyMessage(3.0))
        ours.sendall(pipe_messages.encode_pickle({"x": 1}))
        assert pipe_messages.receive(theirs.recv, (ReadyMessage,), source="s") == ReadyMessage(3.0)
        encoding, body = read_frame(theirs.recv, source="s")
        assert pipe_messages.decode_pickle(encoding, body, source="s") == {"x": 1}
        ours.sendall(pipe_messages.encode_pickle(1))
        with pytest.raises(FrameError, match="where a message was expected"):
            pipe_messages.receive(theirs.recv, (ReadyMessage,), source="s")


def test_the_replay_worker_exits_cleanly_at_the_end_of_its_input():
    proc = subprocess.run([sys.executable, "-m", "astaa_deft.analysis.minimise.replay_pool", "0", "1"],
                          stdin=subprocess.DEVNULL, capture_output=True, timeout=60)
    assert proc.returncode == 0
