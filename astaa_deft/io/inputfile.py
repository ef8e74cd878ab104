"""The one way the tool opens a user's input file: a regular file of bounded size, or one clear error.

A FIFO, a device, a socket handed over as a spec, a policy, a dictionary or a
log would block ``open()`` forever (a FIFO with no writer) or never end a read
(``/dev/zero``). So the kind and the size are taken from ``os.stat`` before
anything is opened, the file is opened with ``O_NONBLOCK`` (should it be
swapped for a FIFO between the ``stat`` and the ``open``, the open returns at
once) and checked again through its descriptor, and a read never takes more
than the kind's cap plus one byte.
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from astaa_deft.model.errors import InputError, Problem

MiB = 1024 * 1024


@dataclass(frozen=True)
class InputKind:
    """What a file is to the tool: how messages name it, the largest accepted, what to give instead."""

    noun: str  # "spec", "test case"…
    max_bytes: int | None  # None: no cap (a log is read record by record)
    expected: str  # what to give instead of a directory or a special file

    @property
    def cap_text(self) -> str:
        return f"{(self.max_bytes or 0) // MiB} MiB"


# Generous: the demo spec is 20 kB, a test case a few kB, the default dictionary 5 kB.
SPEC = InputKind("spec", 64 * MiB, "a SUT spec (YAML file)")
POLICY = InputKind("test case", 10 * MiB, "an XML test case file")
DICTIONARY = InputKind("dictionary", 16 * MiB, "a dictionary (YAML file)")
MESSAGE_TYPE = InputKind("message type file", 1 * MiB, "a ROS 2 .msg file")
LANES = InputKind("lanes file", 16 * MiB, "a lanes file (YAML)")
LOG = InputKind("log", None, "an MCAP log file")

_SPECIAL = ((stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISCHR, "a character device"),
            (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def check_input(path: Path | str, kind: InputKind) -> os.stat_result:
    """The file's ``stat`` when it is a regular file within the kind's cap.

    Raises ``InputError`` naming the file and the fix when it is missing, a
    directory, a special file (judged without opening it) or too large.
    """
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise InputError(Problem(str(path), None, None, f"{kind.noun} file not found", "check the path")) from None
    except OSError as exc:
        raise InputError(Problem(str(path), None, None, f"cannot read the {kind.noun}: {exc.strerror or exc}",
                                 "check the path and its permissions")) from None
    _check_stat(path, info, kind)
    return info


def read_input(path: Path | str, kind: InputKind) -> bytes:
    """The whole content of a checked input file (see :func:`check_input`); raises ``InputError``."""
    with open_input(path, kind) as stream:
        limit = kind.max_bytes
        data = stream.read() if limit is None else stream.read(limit + 1)
    if limit is not None and len(data) > limit:  # grew after the stat
        raise _too_large(path, kind)
    return data


def open_input(path: Path | str, kind: InputKind) -> BinaryIO:
    """A binary stream on a checked input file (see :func:`check_input`), the caller closes it.

    Raises ``InputError`` for what :func:`check_input` refuses and when the
    open itself fails.
    """
    check_input(path, kind)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        raise InputError(Problem(str(path), None, None, f"cannot read the {kind.noun}: {exc.strerror or exc}",
                                 "check the path and its permissions")) from None
    try:
        _check_stat(path, os.fstat(fd), kind)  # the same file as the stat said, not one swapped in since
        os.set_blocking(fd, True)
    except BaseException:
        os.close(fd)
        raise
    return os.fdopen(fd, "rb")


def _check_stat(path: Path | str, info: os.stat_result, kind: InputKind) -> None:
    mode = info.st_mode
    if stat.S_ISDIR(mode):
        raise InputError(Problem(str(path), None, None, "is a directory", f"give {kind.expected}"))
    for test, what in _SPECIAL:
        if test(mode):
            raise InputError(Problem(str(path), None, None, f"is {what}, not a regular file",
                                     f"save the {kind.noun} to a file and give that file"))
    if not stat.S_ISREG(mode):
        raise InputError(Problem(str(path), None, None, "is not a regular file", f"give {kind.expected}"))
    if kind.max_bytes is not None and info.st_size > kind.max_bytes:
        raise _too_large(path, kind)


def _too_large(path: Path | str, kind: InputKind) -> InputError:
    return InputError(Problem(str(path), None, None, f"the {kind.noun} is larger than {kind.cap_text}",
                              f"check that this is {kind.expected}; no real one comes near the cap"))
