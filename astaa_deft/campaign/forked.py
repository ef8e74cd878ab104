"""A case's recorder forked from its warm worker: no interpreter start, no imports, the spec parsed once.

A warm worker (worker.py ``--warm``) has imported everything a recorder
needs and parsed the spec before its payload comes. Started as its own
Python process, the recorder would spend ~0.55 CPU s on the same start-up
again (measured: interpreter, imports, the spec) — a sixth of a demo case's
CPU. Forked from the worker while it is still one thread and has no Zenoh
session, it starts with all of that done. It is a real child process all
the same (its own session and process group, stopped with its parent), it
is driven exactly as a recorder started with ``--warm`` (its ARGS line,
then the spec's text on stdin), and :class:`ForkedRecorder` is a
``subprocess.Popen`` whose waiting, polling and pipes are the standard ones:
only the start differs (fork without exec).
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import traceback

from ..bus.processes import die_with_parent
from ..session import recorder
from ..spec_loader import load_spec_text


class ForkedRecorder(subprocess.Popen):
    """A warm recorder (see ``session/recorder.py``) forked from this process: call it while single-threaded."""

    def __init__(self, spec_text: str, spec_name: str, parsed: object = None):
        """``parsed``: ``spec_text`` parsed already, as ``load_spec_text(spec_text, name=spec_name)`` does."""
        if not single_threaded():  # another thread may hold a lock (Zenoh's runtime, logging) the child would need
            raise RuntimeError("a recorder is forked only from a single-threaded process")
        # Parsed before the fork: the child finds it in memory, as --warm would have parsed it.
        spec = parsed if parsed is not None else load_spec_text(spec_text, name=spec_name)
        self._parsed: dict[tuple[str, str], object] = {(spec_text, spec_name): spec}
        super().__init__(["astaa-deft-recorder"], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                         stderr=subprocess.DEVNULL, text=True)

    def _execute_child(self, args, executable, preexec_fn, close_fds, pass_fds, cwd, env,
                       startupinfo, creationflags, shell, p2cread, p2cwrite, c2pread, c2pwrite,
                       errread, errwrite, *rest) -> None:
        started_read, started_write = os.pipe()  # the child says when it leads its own group (as Popen's does)
        pid = os.fork()
        if pid == 0:  # the recorder
            code = 1
            try:
                os.setsid()  # its own process group, as every helper of a run (stopped by group)
                die_with_parent()
                os.write(started_write, b"1")
                for fd, target in ((p2cread, 0), (c2pwrite, 1), (errwrite, 2)):
                    os.dup2(fd, target)
                os.closerange(3, os.sysconf("SC_OPEN_MAX"))  # nothing of the worker's pipes stays open here
                sys.stdin = open(0, encoding="utf-8", closefd=False)  # noqa: SIM115 - the process's own streams
                sys.stdout = open(1, "w", encoding="utf-8", closefd=False)  # noqa: SIM115
                sys.stderr = open(2, "w", encoding="utf-8", closefd=False)  # noqa: SIM115
                code = recorder.await_arguments(self._parsed)
            except BaseException:  # noqa: BLE001 - a child must never return into the worker's code
                traceback.print_exc()
            finally:
                for stream in (sys.stdout, sys.stderr):
                    with contextlib.suppress(Exception):  # exiting anyway
                        stream.flush()
                os._exit(code)
        self.pid = pid
        self._child_created = True
        os.close(started_write)
        os.read(started_read, 1)  # b"" if it died first: poll() tells the caller
        os.close(started_read)
        # As Popen's own start does once its child runs (the stub does not declare it).
        self._close_pipe_fds(p2cread, p2cwrite, c2pread, c2pwrite, errread, errwrite)  # type: ignore[attr-defined]


def single_threaded() -> bool:
    """Whether this process runs one thread (Python's and any native one, e.g. a Zenoh runtime's)."""
    try:
        return len(os.listdir("/proc/self/task")) == 1
    except OSError:  # no /proc: cannot tell, so no
        return False
