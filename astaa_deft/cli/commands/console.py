"""Terminal output and Ctrl-C handling shared by the long-running commands."""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from types import FrameType
from typing import TextIO

from astaa_deft.model.errors import InputError
from astaa_deft.io.log import records as rec


class StopSignal:
    """While entered, SIGINT/SIGTERM set ``received`` (the signal's name) instead of interrupting, so the
    main thread polls ``requested()`` and shuts down cleanly. Enter and exit on the main thread only."""

    def __init__(self) -> None:
        self.received: str | None = None
        self._old: dict[signal.Signals, signal._HANDLER] = {}

    def __enter__(self) -> StopSignal:
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._old[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum: int, _frame: FrameType | None) -> None:
        # Only plain assignments here: a handler that takes a lock (Event.set) can
        # deadlock against the main thread it interrupted.
        self.received = signal.Signals(signum).name
        _noted[:] = [self.received]

    def requested(self) -> bool:
        """A stop signal arrived since entering."""
        return self.received is not None

    def __exit__(self, *exc: object) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)


# The stop signal this process received last, noted by every handler here: a command made of steps (the demo)
# asks after each step whether to go on, whichever step's handler took the signal; `main` picks 130 or 143.
_noted: list[str] = []


def last_stop() -> str | None:
    """The name of the stop signal (SIGINT, SIGTERM) received since :func:`forget_stop`, or None."""
    return _noted[-1] if _noted else None


def forget_stop() -> None:
    """Start a new command: no stop signal received yet."""
    _noted.clear()


def interrupted_exit_code() -> int:
    """143 after a SIGTERM (128 + 15, as a shell reports a process it terminated), else 130 (Ctrl-C)."""
    return 128 + signal.SIGTERM if last_stop() == signal.SIGTERM.name else 130


@contextlib.contextmanager
def stop_as_interrupt() -> Iterator[None]:
    """SIGTERM raises KeyboardInterrupt, as Ctrl-C does, while this holds, and both are noted (:func:`last_stop`):
    a workflow that ends early with what it has done on a KeyboardInterrupt does so under ``timeout`` or a CI
    job's cancel too. Off the main thread (where no handler can be installed) it does nothing."""
    def interrupt(signum: int, _frame: FrameType | None) -> None:
        _noted[:] = [signal.Signals(signum).name]
        raise KeyboardInterrupt

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = {sig: signal.signal(sig, interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)


def parse_params(items: Iterable[str]) -> dict[str, str]:
    """``KEY=VALUE`` texts as a dict (a later KEY wins); InputError for an item without ``=`` or a key."""
    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise InputError(f"--param '{item}': write it as KEY=VALUE")
        out[key] = value
    return out


class StatusLine:
    """A one-line live status on a terminal; silent when output is not a terminal."""

    def __init__(self, render: Callable[[], str], period: float = 1.0, stream: TextIO = sys.stderr) -> None:
        self.render = render
        self.period = period
        self.stream = stream
        self.enabled = stream.isatty()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> StatusLine:
        if self.enabled and not self._thread.is_alive():
            self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            self.stream.write("\r\033[K" + self.render())
            self.stream.flush()

    def clear(self) -> None:
        if self.enabled:
            self.stream.write("\r\033[K")
            self.stream.flush()

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
            self.clear()


class RateMeter:
    """Messages per second per channel between two calls."""

    def __init__(self, counts: Callable[[], dict[str, int]]) -> None:
        self.counts = counts
        self._last = counts()
        self._last_t = time.monotonic()

    def rates(self) -> dict[str, float]:
        now, t = self.counts(), time.monotonic()
        dt = max(t - self._last_t, 1e-6)
        out = {k: (v - self._last.get(k, 0)) / dt for k, v in now.items()}
        self._last, self._last_t = now, t
        return out


PLAIN_PERIOD_S = 10.0  # a command's progress on a stream that is not a terminal: a line this often


def duration(seconds: float) -> str:
    """Seconds as a person reads them: 42 s, 3m05s, 1h02m."""
    seconds = max(0, round(seconds))
    if seconds < 60:
        return f"{seconds} s"
    minutes, secs = divmod(seconds, 60)
    if minutes < 60:
        return f"{minutes}m{secs:02d}s"
    return f"{minutes // 60}h{minutes % 60:02d}m"


class PlainLines:
    """Progress as plain lines on a stream that is not a terminal (a CI log, a pipe).

    ``show(text)`` hands over the latest state: it is printed at once the
    first time, then every ``period_s`` — whether or not it changed, so a
    log shows the command is alive during a step that takes minutes — and by
    ``close``. The printing thread starts at the first ``show``, so none
    runs while a command forks its workers before that. Each line reads
    ``label: text (elapsed)``.
    """

    def __init__(self, label: str, *, period_s: float = PLAIN_PERIOD_S, stream: TextIO | None = None) -> None:
        self.label = label
        self.period_s = period_s
        self.stream = stream if stream is not None else sys.stderr
        self.started = time.monotonic()
        self.latest: str | None = None
        self.printed: str | None = None
        self._last_print = 0.0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def show(self, text: str) -> None:
        """The latest state (printed at once the first time, else at the next period)."""
        first = self.latest is None
        self.latest = text
        if first:
            self._print()
            self._thread = threading.Thread(target=self._run, daemon=True)
            self._thread.start()
        elif time.monotonic() - self._last_print >= self.period_s:
            self._print()

    def _run(self) -> None:
        while not self._stop.wait(max(0.0, self.period_s - (time.monotonic() - self._last_print))):
            if time.monotonic() - self._last_print >= self.period_s:
                self._print()

    def _print(self) -> None:
        with self._lock:
            text = self.latest
            self._last_print = time.monotonic()
            self.printed = text
            self.stream.write(f"{self.label}: {text} ({duration(time.monotonic() - self.started)} elapsed)\n")
            self.stream.flush()

    def close(self) -> None:
        """Stop the periodic lines; the latest state is printed once more if it was not yet."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
            if self.printed != self.latest:
                self._print()


class CountProgress:
    """``progress(done, total)`` of a long command: a redrawn bar on a terminal, else :class:`PlainLines`;
    both with the rate and the time left at that rate."""

    def __init__(self, label: str, unit: str, *, period_s: float = PLAIN_PERIOD_S,
                 stream: TextIO | None = None) -> None:
        self.unit = unit
        self.stream = stream if stream is not None else sys.stderr
        self.tty = self.stream.isatty()
        self.lines = PlainLines(label, period_s=period_s, stream=self.stream)
        self.started = time.monotonic()

    def text(self, done: int, total: int) -> str:
        elapsed = time.monotonic() - self.started
        rate = done / elapsed if elapsed > 0 else 0.0
        pace = f"{rate:.2f} {self.unit}/s" if rate >= 0.1 else f"{rate * 60:.1f} {self.unit}/min"
        eta = f", ETA {duration((total - done) / rate)}" if rate > 0 and done < total else ""
        return f"{done}/{total} {self.unit}, {pace}{eta}"

    def __call__(self, done: int, total: int) -> None:
        text = self.text(done, total)
        if not self.tty:
            self.lines.show(text)
            return
        if total == 0:
            return
        width = 30
        filled = int(width * done / total)
        self.stream.write(f"\r\033[K  [{'#' * filled}{'.' * (width - filled)}] {text}")
        if done == total:
            self.stream.write("\r\033[K")
        self.stream.flush()

    def close(self) -> None:
        if self.tty:
            self.stream.write("\r\033[K")
            self.stream.flush()
        else:
            self.lines.close()


def say(message: str) -> None:
    print(message, flush=True)


def format_event(record: rec.Record) -> str | None:
    """One event as the console shows it (None: not shown)."""
    if isinstance(record, rec.ProcessExit):
        if record.during_shutdown:
            return None
        text = f"!! {record.describe(with_pid=False)}"
        tail = record.stderr_tail.strip().splitlines()
        if tail:
            text += "\n   " + "\n   ".join(tail[-5:])
        return text
    if isinstance(record, rec.Violation):
        from astaa_deft.engine.monitor.violation import format_violation

        return format_violation(record)
    if isinstance(record, rec.MutationRecord):
        fields = ", ".join(f"{c.path}: {_short(c.old)} → {_short(c.new)}" for c in record.fields)
        index = f" #{record.message_index}" if record.message_index is not None else ""
        return (f"~~ {record.action} on '{record.channel}'{index} (policy {record.policy})"
                + (f": {fields}" if fields else ""))
    if isinstance(record, rec.UndeclaredKey):
        return f"-- undeclared key '{record.key}' from '{record.module}': {record.note}"
    return None


def _short(value: object, limit: int = 40) -> str:
    text = value if isinstance(value, str) else repr(value)
    return text if len(text) <= limit else text[: limit - 1] + "…"
