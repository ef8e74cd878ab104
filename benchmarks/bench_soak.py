"""Soak: a long run at 1 kHz through the star with the recorder, then one minute at the top rate.

    python benchmarks/bench_soak.py [--minutes 10] [--top-seconds 60]

Real processes on loopback: the benchmark source and sink (tests-free,
third-party style, benchmarks/sut) wired by the tool as `astaa-deft proxy
--record` does (`run_session`, star mode, recorder in its own process).

Phase 1: ``--minutes`` at 1,000 msg/s. Phase 2: a probe sends 200,000
messages flat out; then ``--top-seconds`` at 80 % of the probe's rate, stepping
down to 60 % and 40 % until a soak keeps sent = delivered = recorded at the
asked rate (the highest rate the star sustains, to that resolution).
For each phase it prints sent (what the source published, with Zenoh's
blocking congestion control), forwarded (through the star), delivered (the
sink), recorded (the recorder's own count, and the messages read back from
the log), and the resident memory (RSS) of the tool and of the recorder,
sampled once the stream flows and again just before the end, plus the RSS
over time (one sample every ``--sample-seconds``) so growth can be told from
levelling off. Each sample also gives the tool's C heap as glibc's
``mallinfo2`` counts it (every arena: Python, Zenoh's Rust side, all
threads): in use, and free but kept by malloc for reuse; and at the end the
tool's RSS before and after ``malloc_trim(0)``. RSS that rises while "in
use" stays flat is memory malloc kept after a transient backlog drained, not
data the tool holds. Asserts nothing.

    python benchmarks/bench_soak.py --rate 25000 --seconds 60 --sample-seconds 5 [--tracemalloc]

runs one soak at a fixed rate instead (the RSS at a high rate);
``--tracemalloc`` also lists the lines of Python code whose allocations grew
most between the first sample after warm-up and the last (it slows the tool).
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import json
import os
import tempfile
import time
import tracemalloc
from pathlib import Path

from astaa_deft.io.log.reader import read_log
from astaa_deft.engine.session import RunOptions, RunView, run_session
from astaa_deft.engine.spec.loader import load_spec

SUT = Path(__file__).parent / "sut"
SPEC = load_spec(SUT / "bench.yaml")
PROBE_COUNT = 200_000  # several seconds flat out: long enough that buffers do not hide the limit
STEP_DOWN = (0.8, 0.6, 0.4)
WARM_UP_SECONDS = 5.0  # the first RSS sample: once the stream flows and buffers have grown to their working size
SAMPLE_SECONDS = [30.0]  # the RSS series' interval (--sample-seconds)
TRACE_PYTHON = [False]  # --tracemalloc: which lines of Python code the tool's growth was allocated by


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                                       "fsmblks", "uordblks", "fordblks", "keepcost")]


LIBC = ctypes.CDLL(None)  # once: each CDLL() would allocate in the process it measures
MALLINFO2 = getattr(LIBC, "mallinfo2", None)  # glibc ≥ 2.33
if MALLINFO2 is not None:
    MALLINFO2.restype = _MallInfo2


def malloc_kib() -> tuple[int, int] | None:
    """The tool process's C heap (Python, Zenoh's Rust side and every thread's arena): (in use, free but kept), KiB.

    RSS that grows while "in use" stays flat is memory malloc keeps for reuse
    (arenas), not data the tool holds on to.
    """
    if MALLINFO2 is None:
        return None
    info = MALLINFO2()
    return (info.uordblks + info.hblkhd) // 1024, info.fordblks // 1024


def threads(pid: int) -> int | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("Threads:"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


def rss_kib(pid: int) -> int | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        return None
    return None


def soak(count: int, rate: float, label: str, size: int = 200) -> dict:
    """One run of ``count`` messages at ``rate`` Hz (0: flat out) through the star, recorded."""
    with tempfile.TemporaryDirectory(prefix="astaa-soak-") as tmp:
        run_dir = Path(tmp)
        log = run_dir / "soak.mcap"
        sink = run_dir / "sink.json"
        expected = count / rate if rate else count / 5000.0
        options = RunOptions(mode="star", record=log, run_dir=run_dir, time_limit=expected * 3 + 120,
                             params={"count": str(count), "rate": str(rate), "size": str(size)})
        samples: dict[str, dict] = {}
        series: list[dict] = []
        t0 = [0.0]

        snapshots: list[tracemalloc.Snapshot] = []

        def started(run: RunView) -> None:
            t0[0] = time.monotonic()
            if TRACE_PYTHON[0]:
                tracemalloc.start()

        def stop_when(run: RunView) -> str | None:
            now = time.monotonic() - t0[0]
            recorder = run.recorder_pid
            sample = {"t": now, "tool": rss_kib(os.getpid()), "recorder": rss_kib(recorder) if recorder else None,
                      "forwarded": run.counts().get("data", 0), "malloc": malloc_kib(),
                      "threads": threads(os.getpid())}
            if "start" not in samples and now >= WARM_UP_SECONDS and sample["forwarded"]:
                samples["start"] = sample
            if not series or now - series[-1]["t"] >= SAMPLE_SECONDS[0]:
                series.append(sample)
                if TRACE_PYTHON[0] and now >= WARM_UP_SECONDS:
                    snapshots[1:] = []  # keep the first (once the stream flows) and the latest
                    snapshots.append(tracemalloc.take_snapshot())
            if sink.exists():
                # What the tool's RSS holds at the end that malloc merely keeps for reuse: give it back and look.
                before = rss_kib(os.getpid())
                with contextlib.suppress(AttributeError):  # not glibc
                    LIBC.malloc_trim(0)
                samples["trim"] = {"before": before, "after": rss_kib(os.getpid())}
                return "sink done"
            samples["end"] = sample  # the last sample before the end
            return None

        outcome = run_session(SPEC, options, stop_when=stop_when, on_start=started)
        if TRACE_PYTHON[0]:
            tracemalloc.stop()
            if len(snapshots) == 2:
                print("  Python allocations that grew most in the tool, first sample → last (tracemalloc):")
                for stat in snapshots[1].compare_to(snapshots[0], "lineno")[:8]:
                    print(f"    {stat.size_diff / 1024:+9.1f} KiB {stat.count_diff:+8d} blocks  {stat.traceback}")
        result = json.loads(sink.read_text()) if sink.exists() else {"received": 0, "rate": 0.0, "seconds": 0.0}
        in_log = len(read_log(log).on("bench/data"))
        out = {"label": label, "sent": count, "forwarded": outcome.sent.get("data", 0),
               "delivered": result["received"], "recorded": outcome.recorded.get("data", 0), "in_log": in_log,
               "rate": result["rate"], "seconds": result["seconds"], "complete": outcome.complete,
               "end": outcome.end_reason, "log_bytes": log.stat().st_size,
               "rss_start": samples.get("start"), "rss_end": samples.get("end"), "rss_series": series,
               "trim": samples.get("trim")}
        report(out)
        return out


def report(r: dict) -> None:
    ok = r["sent"] == r["forwarded"] == r["delivered"] == r["recorded"] == r["in_log"]
    print(f"\n== {r['label']} ==")
    print(f"  {r['seconds']:.1f} s of stream at {r['rate']:,.0f} msg/s; run ended: {r['end']}; "
          f"log {r['log_bytes'] / 1e6:.1f} MB, finished cleanly: {r['complete']}")
    print(f"  sent {r['sent']:,}  forwarded {r['forwarded']:,}  delivered {r['delivered']:,}  "
          f"recorded {r['recorded']:,}  read back {r['in_log']:,}  → {'all equal' if ok else 'MISMATCH'}")
    start, end = r["rss_start"], r["rss_end"]
    if start and end:
        span = end["t"] - start["t"]
        for who in ("tool", "recorder"):
            if start[who] and end[who]:
                growth = end[who] - start[who]
                per_min = growth / span * 60 if span > 0 else 0.0
                print(f"  RSS {who:8}: {start[who] / 1024:7.1f} MiB at +{start['t']:.0f} s → {end[who] / 1024:7.1f} MiB "
                      f"at +{end['t']:.0f} s ({growth / 1024:+.1f} MiB, {per_min / 1024:+.2f} MiB/min)")
    trim = r.get("trim")
    if trim and trim["before"] and trim["after"]:
        print(f"  RSS tool at the end: {trim['before'] / 1024:.1f} MiB; after malloc_trim(0): "
              f"{trim['after'] / 1024:.1f} MiB (the difference was free memory malloc kept for reuse)")
    if r["rss_series"]:
        print("  RSS over time (MiB): tool / recorder; the tool's malloc heap in use / free but kept; the tool's "
              "threads; forwarded so far")
        for s in r["rss_series"]:
            tool = f"{s['tool'] / 1024:6.1f}" if s["tool"] else "     -"
            rec = f"{s['recorder'] / 1024:6.1f}" if s["recorder"] else "     -"
            heap = (f"{s['malloc'][0] / 1024:6.1f} / {s['malloc'][1] / 1024:6.1f}" if s["malloc"]
                    else "     - /      -")
            print(f"    +{s['t']:5.0f} s  {tool} / {rec}   heap {heap}   {s['threads'] or '-':>3} threads   "
                  f"{s['forwarded']:>10,}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="length of the 1 kHz soak (default 10)")
    ap.add_argument("--top-seconds", type=float, default=60.0, help="length of the top-rate soak (default 60)")
    ap.add_argument("--sample-seconds", type=float, default=30.0, help="interval of the RSS series (default 30)")
    ap.add_argument("--rate", type=float, help="one soak at this rate (msg/s) instead of the phases")
    ap.add_argument("--seconds", type=float, default=60.0, help="length of the --rate soak (default 60)")
    ap.add_argument("--tracemalloc", action="store_true",
                    help="also trace the tool's Python allocations (slows the tool: for finding what grows)")
    args = ap.parse_args()
    SAMPLE_SECONDS[0] = args.sample_seconds
    TRACE_PYTHON[0] = args.tracemalloc
    if args.rate:
        soak(int(args.seconds * args.rate), args.rate, f"{args.seconds:g} s at {args.rate:,.0f} msg/s")
        return 0

    soak(int(args.minutes * 60 * 1000), 1000.0, f"{args.minutes:g} min at 1 kHz through the star + recorder")
    probe = soak(PROBE_COUNT, 0.0, f"probe: {PROBE_COUNT:,} messages flat out")
    # A burst is absorbed by buffers; sustained is what keeps sent = delivered = recorded at the asked rate
    # for the whole soak. Step down from 80 % of the probe until a soak holds (or report the last one).
    for share in STEP_DOWN:
        top = max(1000.0, round(probe["rate"] * share, -2))
        r = soak(int(args.top_seconds * top), top, f"{args.top_seconds:g} s at {top:,.0f} msg/s "
                 f"({share:.0%} of the probe's flat-out rate)")
        held = r["sent"] == r["delivered"] == r["recorded"] == r["in_log"] and r["rate"] >= 0.95 * top
        if held:
            print(f"\nthe star + recorder sustained {top:,.0f} msg/s for {args.top_seconds:g} s with nothing lost")
            break
        print(f"  not sustained at {top:,.0f} msg/s (stream {r['rate']:,.0f} msg/s, "
              f"{r['delivered'] - r['recorded']:,} delivered but not recorded)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
