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
sampled once the stream flows and again just before the end. Asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from astaa_deft.log.reader import read_log
from astaa_deft.session import BusRun, RunOptions, run_session
from astaa_deft.spec_loader import load_spec

SUT = Path(__file__).parent / "sut"
SPEC = load_spec(SUT / "bench.yaml")
PROBE_COUNT = 200_000  # several seconds flat out: long enough that buffers do not hide the limit
STEP_DOWN = (0.8, 0.6, 0.4)
WARM_UP_SECONDS = 5.0  # the first RSS sample: once the stream flows and buffers have grown to their working size


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
        t0 = [0.0]

        def started(run: BusRun) -> None:
            t0[0] = time.monotonic()

        def stop_when(run: BusRun) -> str | None:
            now = time.monotonic() - t0[0]
            recorder = run.recorder.pid if run.recorder is not None else None
            sample = {"t": now, "tool": rss_kib(os.getpid()), "recorder": rss_kib(recorder) if recorder else None,
                      "forwarded": run.counts().get("data", 0)}
            if "start" not in samples and now >= WARM_UP_SECONDS and sample["forwarded"]:
                samples["start"] = sample
            if sink.exists():
                return "sink done"
            samples["end"] = sample  # the last sample before the end
            return None

        outcome = run_session(SPEC, options, stop_when=stop_when, on_start=started)
        result = json.loads(sink.read_text()) if sink.exists() else {"received": 0, "rate": 0.0, "seconds": 0.0}
        in_log = len(read_log(log).on("bench/data"))
        out = {"label": label, "sent": count, "forwarded": outcome.sent.get("data", 0),
               "delivered": result["received"], "recorded": outcome.recorded.get("data", 0), "in_log": in_log,
               "rate": result["rate"], "seconds": result["seconds"], "complete": outcome.complete,
               "end": outcome.end_reason, "log_bytes": log.stat().st_size,
               "rss_start": samples.get("start"), "rss_end": samples.get("end")}
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


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="length of the 1 kHz soak (default 10)")
    ap.add_argument("--top-seconds", type=float, default=60.0, help="length of the top-rate soak (default 60)")
    args = ap.parse_args()

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
