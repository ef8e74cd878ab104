"""What each policy of a test case did in one run, and why one that touched nothing may not have.

A test case whose window is "5–7 s after the start" touches nothing if the
SUT started 20 s late (a module waiting on another's liveliness), if its
channel was silent then, or if the run ended first. "mutations applied: 0"
alone hides which; :func:`untouched_reason` says which of these the run's
own traffic points at. Pure functions over a typed record: the engine
fills it (``Interceptor.applications``), the session logs it and the
commands print it.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ChannelTraffic:
    """A target channel's real messages as the interception saw them (seconds since the run's start)."""

    channel: str
    count: int
    first_s: float | None
    last_s: float | None


@dataclass(frozen=True, kw_only=True)
class PolicyApplications:
    testcase: str
    policy: str
    action: str
    window_start_s: float | None  # absolute, seconds since the run's start; None: the window never opened
    window_end_s: float | None  # None: open to the end of the run
    anchor: str | None  # "message N on channel C" for a window counted from a message
    in_window: int  # real messages of its channels that arrived while its window was open
    touched: int  # messages it changed, dropped, delayed, injected, ... (mutation events naming it)
    traffic: tuple[ChannelTraffic, ...]
    run_end_s: float  # when the interception stopped, seconds since the run's start

    def to_json(self) -> dict:
        return {"testcase": self.testcase, "policy": self.policy, "action": self.action,
                "window_start_s": self.window_start_s, "window_end_s": self.window_end_s, "anchor": self.anchor,
                "in_window": self.in_window, "touched": self.touched, "run_end_s": self.run_end_s,
                "traffic": [{"channel": t.channel, "count": t.count, "first_s": t.first_s, "last_s": t.last_s}
                            for t in self.traffic],
                "untouched_reason": untouched_reason(self)}


def _s(value: float) -> str:
    return f"{value:.1f} s"


def _window(app: PolicyApplications) -> str:
    assert app.window_start_s is not None
    # The user's own bounds, as written (an anchored window's are shifted by the anchor's arrival).
    end = "the end" if app.window_end_s is None else f"{app.window_end_s:.3g} s"
    return f"[{app.window_start_s:.3g} s, {end})"


def untouched_reason(app: PolicyApplications) -> str | None:
    """Why the policy touched no message (None if it touched one): what the run's traffic points at."""
    if app.touched:
        return None
    if app.window_start_s is None:
        return (f"its window never opened: its anchor ({app.anchor}) never arrived — "
                f"the SUT may have started late or that channel was silent")
    if app.run_end_s < app.window_start_s:
        return f"the run ended at {_s(app.run_end_s)}, before its window {_window(app)} opened"
    closed = app.window_end_s is not None and app.window_end_s <= app.run_end_s
    ended = "" if closed else f" (the run ended at {_s(app.run_end_s)}, inside it)"
    if app.in_window:
        return (f"{app.in_window} message(s) arrived in its window {_window(app)}{ended} but none was touched: "
                f"its selection (every / probability / limit) or its action did not apply to them")
    parts = []
    for t in app.traffic:
        if t.count == 0 or t.first_s is None or t.last_s is None:
            parts.append(f"'{t.channel}' carried no message in the whole run (silent)")
        elif app.window_end_s is not None and t.first_s >= app.window_end_s:
            parts.append(f"the first message on '{t.channel}' came at {_s(t.first_s)}, after the window "
                         f"had closed — the SUT started late (e.g. a module waiting on another)")
        elif t.last_s < app.window_start_s:
            parts.append(f"'{t.channel}' fell silent at {_s(t.last_s)}, before the window opened")
        else:
            parts.append(f"'{t.channel}' was silent while the window was open")
    why = "; ".join(parts) or "it targets no channel"
    return f"no message arrived in its window {_window(app)}{ended}: {why}"
