"""One way to write output: check the place before the work, and say plainly why a write failed.

Every command that writes (``generate -o``, ``extract -o``, ``minimise -o``,
``proxy --run-dir`` and ``--record``, ``fuzz -o``, ``report``, ``demo``,
``spec discover -o``) checks its output place with :func:`ready_dir` or
:func:`ready_file` before any long work, and runs its writing inside
:func:`writing`, which turns the operating system's refusals (permission,
read-only file system, file size limit, full disk, no usable temporary
directory, a file in the way) into one :class:`OutputError`: the path, what
went wrong and the fix, exit code :data:`EXIT_CANNOT_WRITE`. Files written
through :func:`write_atomic` are either whole or absent, so what was written
before a failure stays readable.

Never through a link: :func:`write_atomic` writes a new temporary file
(created exclusively, so no link planted at its name is followed) and renames
it over the target, which replaces a link there rather than writing where it
points; a file written as it goes (a log) is opened by :func:`open_new`,
which refuses a symbolic link at the path (:class:`OutputError`) and replaces
an existing file by a new one (a hard link elsewhere keeps its content).
:func:`ready_file` refuses a link before the work starts.

A file size limit (``ulimit -f``) sends SIGXFSZ, whose default action kills
the process without a word; the CLI ignores it (:func:`ignore_file_size_signal`)
so the write fails with EFBIG instead, which is reported like a full disk.
"""

from __future__ import annotations

import contextlib
import errno
import os
import resource
import shutil
import signal
import stat
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, ClassVar

from astaa_deft.model.errors import AstaaDeftError, Problem

EXIT_CANNOT_WRITE = 4  # the CLI's exit code for an output place that cannot take the output
MIN_ROOM_BYTES = 64 * 1024  # less free space (or a smaller file size limit) than this: refused up front

# errno → (what went wrong, the fix); {option} is the command-line option that named the place.
_REASONS: dict[int, tuple[str, str]] = {
    errno.EACCES: ("permission denied", "give a place you can write with {option}, or change its permissions"),
    errno.EPERM: ("operation not permitted", "give a place you can write with {option}, or change its permissions"),
    errno.EROFS: ("the file system is read-only", "give a place on a writable file system with {option}"),
    errno.EFBIG: ("the file size limit was reached (ulimit -f)",
                  "raise the limit (ulimit -f unlimited) or give a place with room for the output"),
    errno.ENOSPC: ("no space left on the device", "free some space, or give a place with room with {option}"),
    errno.EDQUOT: ("the disk quota is exhausted", "free some space, or give a place with room with {option}"),
    errno.ENOTDIR: ("a file is in the way where a folder is needed", "give a folder path with {option}"),
    errno.EISDIR: ("is a folder, not a file", "give a file path with {option}"),
    errno.EEXIST: ("a file is in the way", "remove it, or give another path with {option}"),
}


class OutputError(AstaaDeftError):
    """The output place cannot take the output: exit code :data:`EXIT_CANNOT_WRITE`, one line naming path and fix.

    Not an :class:`~astaa_deft.model.errors.InputError`: code that skips a case
    with bad input must not skip past a full disk.
    """

    exit_code: ClassVar[int | None] = EXIT_CANNOT_WRITE

    def __init__(self, problem: Problem):
        self.problem = problem
        super().__init__(str(problem))


@dataclass(frozen=True)
class Place:
    """Where a command writes: the path and the option that named it (for the message's fix)."""

    path: Path
    option: str


def ignore_file_size_signal() -> None:
    """Let a write past ``ulimit -f`` fail with EFBIG (reported) instead of SIGXFSZ killing the process."""
    if hasattr(signal, "SIGXFSZ"):
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)


def refusal(exc: OSError, place: Place, *, at_place: bool = False) -> OutputError:
    """The :class:`OutputError` for an operating-system refusal while writing at ``place``.

    The message names the file the refusal was about, or ``place.path`` itself with ``at_place``
    (or when the error names no file).
    """
    where = exc.filename if exc.filename and not at_place else place.path
    if exc.errno == errno.ENOENT and exc.filename is None:  # tempfile's "No usable temporary directory"
        return _no_temp_dir(exc)
    what, fix = _REASONS.get(exc.errno or 0, (exc.strerror or str(exc), "give another place with {option}"))
    return OutputError(Problem(str(where), None, None, f"cannot write here: {what}", fix.format(option=place.option)))


def is_write_refusal(exc: OSError, place: Place) -> bool:
    """Whether ``exc`` is the output place refusing a write (not, say, an unreadable input)."""
    if exc.errno in (errno.EFBIG, errno.ENOSPC, errno.EDQUOT, errno.EROFS):
        return True  # only a write can fail these ways
    if exc.errno == errno.ENOENT and exc.filename is None and "temporary directory" in str(exc):
        return True
    if exc.errno not in _REASONS or not exc.filename:
        return False
    return _under(Path(os.fsdecode(exc.filename)), place.path)


@contextlib.contextmanager
def writing(*places: Place) -> Iterator[None]:
    """Run the writing of a command: a refusal at one of ``places`` becomes its :class:`OutputError`."""
    try:
        yield
    except OSError as exc:
        for place in places:
            if is_write_refusal(exc, place):
                raise refusal(exc, place) from None
        raise


def ready_dir(place: Place, *, temp: bool = False) -> Path:
    """Make sure ``place.path`` is a folder that can take files, creating it; checked before the work starts.

    Refuses (:class:`OutputError`) a file in the way, a folder that cannot be
    written (a probe file is created, written and removed), less room than
    :data:`MIN_ROOM_BYTES` (free space or the file size limit) and, with
    ``temp``, an unusable temporary directory. Returns the path.
    """
    path = place.path
    if path.exists() and not path.is_dir():
        raise OutputError(Problem(str(path), None, None, "is a file, not a folder",
                                  f"give a folder path with {place.option} (it is created if missing)"))
    try:
        path.mkdir(parents=True, exist_ok=True)
        _probe(path)
    except FileExistsError:  # a file where a parent folder should be
        raise OutputError(Problem(str(path), None, None, "a file is in the way where a folder is needed",
                                  f"give a folder path with {place.option}")) from None
    except OSError as exc:  # whatever the reason (a folder under /proc, say), this place takes no files
        raise refusal(exc, place, at_place=True) from None
    _check_room(path, place)
    if temp:
        check_temp_dir()
    return path


def ready_file(place: Place, *, overwrite: bool = True) -> Path:
    """Make sure ``place.path`` can be written as a file in an existing folder; checked before the work starts.

    Refuses (:class:`OutputError`) a folder at the path, an existing file
    unless ``overwrite``, a folder that cannot be written and too little
    room. A missing folder is the caller's to refuse or create. The file is
    not created; an existing one is left as it is.
    """
    path = place.path
    if path.is_symlink():
        raise link_refusal(path, place.option)
    if path.is_dir():
        raise OutputError(Problem(str(path), None, None, "is a folder, not a file",
                                  f"give a file path with {place.option}"))
    if path.exists() and not overwrite:
        raise OutputError(Problem(str(path), None, None, "a file is already there",
                                  f"remove it, or give another path with {place.option}"))
    folder = path.parent if str(path.parent) else Path(".")
    try:
        _probe(folder)
    except OSError as exc:
        raise refusal(exc, place, at_place=True) from None
    _check_room(folder, place)
    return path


def check_temp_dir() -> None:
    """Refuse (:class:`OutputError`) when no temporary directory takes a small file (full, read-only, size limit)."""
    try:
        with tempfile.TemporaryFile(prefix="astaa-deft-probe-") as f:
            f.write(b"\0" * 4096)
            f.flush()
    except OSError as exc:
        raise _no_temp_dir(exc) from None


def write_atomic(path: Path, data: bytes | str) -> None:
    """Write ``path`` whole or not at all: a new temporary file beside it, renamed over it once written.

    The temporary file is created exclusively (a link planted at its name is
    never followed) and the rename replaces whatever is at ``path`` — a link
    too — instead of writing through it. On a failure the temporary file is
    removed and the OSError propagates (wrap the caller in :func:`writing`);
    an existing file at ``path`` stays as it was.
    """
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=path.parent)
    tmp = Path(name)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data.encode() if isinstance(data, str) else data)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_NEW_FILE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)


def open_new(path: Path, option: str = "the output path") -> BinaryIO:
    """``path`` opened for writing as a new file (for a file written as it goes, such as a log).

    A symbolic link at ``path`` is refused (:class:`OutputError`, exit 4): the
    tool never writes through a link. An existing file is removed first and a
    new one created in its place (exclusively: a link planted in between is
    refused too), so a hard link to it elsewhere keeps its content.
    """
    path = Path(path)
    if path.is_symlink():
        raise link_refusal(path, option)
    with contextlib.suppress(FileNotFoundError):
        if stat.S_ISREG(os.lstat(path).st_mode):  # a regular file only: never a device, a FIFO, a folder
            path.unlink()
    try:
        fd = os.open(path, _NEW_FILE, 0o666)
    except FileExistsError:
        raise link_refusal(path, option) if path.is_symlink() else OutputError(Problem(
            str(path), None, None, "is not a regular file (or one appeared there while it was being replaced)",
            f"give the path of a regular file with {option}")) from None
    return os.fdopen(fd, "wb")


def link_refusal(path: Path, option: str) -> OutputError:
    """The refusal of an output path that is a symbolic link."""
    return OutputError(Problem(str(path), None, None, "is a symbolic link: the tool never writes through a link",
                               f"remove the link, or give the path of a new file with {option}"))


def _probe(folder: Path) -> None:
    probe = folder / f".astaa-deft-probe-{os.getpid()}"
    try:
        with open(probe, "wb") as f:
            f.write(b"\0")
    finally:
        with contextlib.suppress(OSError):
            probe.unlink()


def _check_room(folder: Path, place: Place) -> None:
    free = shutil.disk_usage(folder).free
    limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    if free < MIN_ROOM_BYTES:
        raise OutputError(Problem(str(folder), None, None, f"no room to write: {free} bytes free",
                                  f"free some space, or give a place with room with {place.option}"))
    if limit != resource.RLIM_INFINITY and limit < MIN_ROOM_BYTES:
        raise OutputError(Problem(str(folder), None, None,
                                  f"no room to write: the file size limit is {limit} bytes (ulimit -f)",
                                  "raise the limit (ulimit -f unlimited)"))


def _no_temp_dir(exc: OSError) -> OutputError:
    where = f"TMPDIR={os.environ['TMPDIR']}" if os.environ.get("TMPDIR") else "the temporary directory"
    why = exc.strerror or str(exc)
    return OutputError(Problem(where, None, None, f"no usable temporary directory: {why}",
                               "set TMPDIR to a writable folder with free space (and no ulimit -f below 64 KiB)"))


def _under(path: Path, folder: Path) -> bool:
    path, folder = Path(os.path.abspath(path)), Path(os.path.abspath(folder))
    return path == folder or folder in path.parents


def subdir_inside(root: Path, *names: str, option: str) -> Path:
    """``root/names[0]/names[1]/…``, each folder created if missing, none of them a link (OutputError then).

    For folders a command derives inside its own output folder (a campaign's ``verify/<run>/``): a link planted
    at one of these names is refused, never followed, so nothing is written outside ``root``. Each name is one
    path component (no '/', not '.' or '..'): the caller checked it (``model/data_names.py``).
    """
    here = root
    for name in names:
        assert name and "/" not in name and "\0" not in name and name not in (".", ".."), name
        here = here / name
        if here.is_symlink():
            raise link_refusal(here, option)
        try:
            here.mkdir(exist_ok=True)
        except FileExistsError:
            raise OutputError(Problem(str(here), None, None, "a file is in the way where a folder is needed",
                                      f"move it away, or give another folder with {option}")) from None
        if here.is_symlink() or not here.is_dir():  # raced in after the check
            raise link_refusal(here, option)
    return here
