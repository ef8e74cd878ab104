"""The modules' output, line by line, as the run goes: for the log and for ``log`` invariants.

The launcher writes each module's stdout and stderr to one file in the run
directory (``<module>.log``). A follower thread reads what was appended
every ``POLL_SECONDS``, splits it into lines (a partial last line waits for
its end) and hands each line to ``on_line(module, text, time_ns)``, dated
when it was read. A chatty module cannot flood the log: after
``MAX_LINES_PER_MODULE`` lines its further output is counted, not passed
on, and ``dropped`` says how many were left out.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from pathlib import Path

POLL_SECONDS = 0.1
MAX_LINE_CHARS = 2000
MAX_LINES_PER_MODULE = 20_000
READ_CHUNK = 1 << 20


class ModuleOutputFollower:
    def __init__(self, files: dict[str, Path], on_line: Callable[[str, str, int], None]):
        self._files = dict(files)
        self._on_line = on_line
        self._offsets = {name: 0 for name in files}
        self._partial = {name: b"" for name in files}
        self.lines = {name: 0 for name in files}
        self.dropped = {name: 0 for name in files}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="module-output", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        """Read what is left (the modules have stopped) and end the thread."""
        self._stop.set()
        self._thread.join(timeout=10.0)
        self._poll(final=True)

    def _run(self) -> None:
        while not self._stop.wait(POLL_SECONDS):
            self._poll()

    def _poll(self, final: bool = False) -> None:
        for name, path in self._files.items():
            try:
                with open(path, "rb") as f:
                    f.seek(self._offsets[name])
                    data = f.read(READ_CHUNK)
            except OSError:  # not created yet, or gone with its run directory
                continue
            if not data and not (final and self._partial[name]):
                continue
            self._offsets[name] += len(data)
            text = self._partial[name] + data
            parts = text.split(b"\n")
            self._partial[name] = parts.pop() if not final else b""
            if final and parts and parts[-1] == b"":
                parts.pop()
            now = time.time_ns()
            for raw in parts:
                self._line(name, raw, now)

    def _line(self, name: str, raw: bytes, time_ns: int) -> None:
        if self.lines[name] >= MAX_LINES_PER_MODULE:
            self.dropped[name] += 1
            return
        self.lines[name] += 1
        line = raw.rstrip(b"\r").decode("utf-8", errors="replace")
        if len(line) > MAX_LINE_CHARS:
            line = line[:MAX_LINE_CHARS] + "…"
        self._on_line(name, line, time_ns)
