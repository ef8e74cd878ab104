"""Proxy speed, measured in one run: direct Zenoh vs the star vs star + recorder.

    python benchmarks/bench_proxy.py [--quick]

Every figure comes from real processes on loopback: a source and a sink that
import nothing from astaa-deft, wired either directly (peer to peer) or by
the tool (`run_session`, as `astaa-deft proxy` does). Prints absolute figures and
the ratios the targets are stated in; asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from astaa_deft.engine.bus import zenoh_config as zc
from astaa_deft.engine.bus.processes import stop_process
from astaa_deft.engine.session import RunOptions, RunView, run_session
from astaa_deft.engine.intercept import load_interceptor
from astaa_deft.engine.spec.loader import load_spec

SUT = Path(__file__).parent / "sut"
SPEC = load_spec(SUT / "bench.yaml")
MONITORED = load_spec(SUT / "bench_monitored.yaml")
SET_POLICY = SUT / "set_every_message.xml"
RESULT_TIMEOUT = 120.0


def wait_result(path: Path, timeout: float = RESULT_TIMEOUT) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if path.exists():
            return json.loads(path.read_text())
        time.sleep(0.05)
    raise RuntimeError(f"no result at {path}")


def run_direct(params: dict[str, str], spec=SPEC, sut: Path = SUT, timeout: float = RESULT_TIMEOUT) -> dict:
    """Source and sink as plain Zenoh peers, connected to each other: no tool at all."""
    with tempfile.TemporaryDirectory() as tmp:
        run_dir = Path(tmp)
        ep = zc.loopback_endpoint()
        cfgs = {"sink": zc.config_dict(mode="peer", listen=[ep]),
                "source": zc.config_dict(mode="peer", connect=[ep])}
        procs = []
        try:
            for module in spec.modules:
                cfg = zc.write_config_file(cfgs[module.name], run_dir / f"{module.name}.json5")
                values = {**spec.params, **params, "python": sys.executable, "spec_dir": str(sut),
                          "run_dir": str(run_dir), "zenoh_config": str(cfg), "module": module.name}
                argv = [a.format_map(values) for a in module.command]
                procs.append(subprocess.Popen(argv, env={**os.environ, "ZENOH_CONFIG": str(cfg)},
                                              start_new_session=True, stdout=subprocess.DEVNULL))
                time.sleep(0.5)
            return wait_result(run_dir / "sink.json", timeout)
        finally:
            for p in procs:
                stop_process(p, grace=3.0)


def cpu_seconds(who: int) -> float:
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


def thread_cpu() -> dict[str, float]:
    """CPU seconds of this process's live threads by kind: Zenoh's runtime threads by name, Python's as 'python'.

    (Linux: /proc/self/task; Zenoh names its threads rx-N, tx-N, net-N, ...;
    Python threads keep the process's name.) Empty where /proc is missing.
    """
    out: dict[str, float] = {}
    ticks = os.sysconf("SC_CLK_TCK")
    for task in Path("/proc/self/task").glob("*"):
        try:
            name = (task / "comm").read_text().strip().rstrip("0123456789-") or "?"
            fields = (task / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:  # the thread ended meanwhile
            continue
        kind = name if name in ("rx", "tx", "net", "acc", "app") else "python"
        out[kind] = out.get(kind, 0.0) + (int(fields[11]) + int(fields[12])) / ticks
    return out


def process_cpu(pid: int) -> float | None:
    """CPU seconds a live process has used so far (Linux /proc); None if it is gone or /proc is missing."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def settled_cpu(pid: int, quiet: float = 0.3, limit: float = 30.0) -> float | None:
    """A process's CPU seconds once it stopped using CPU (a recorder that has written its backlog)."""
    last, deadline = process_cpu(pid), time.monotonic() + limit
    while last is not None and time.monotonic() < deadline:
        time.sleep(quiet)
        now = process_cpu(pid)
        if now is None or now - last < 0.02:  # at most two clock ticks in the quiet time: idle
            return now if now is not None else last
        last = now
    return last


def run_tool(params: dict[str, str], mode: str, record: bool, spec=SPEC, policy: Path | None = None,
             timeout: float = RESULT_TIMEOUT) -> tuple[dict, dict]:
    """One run through the tool; the sink's result gains the CPU the tool (and its recorder) spent per message.

    CPU per message is the steadier figure on a shared machine: a rate falls
    when other processes take the cores, CPU per message hardly moves. The
    tool's share is also split by thread kind (``tool_threads_us``), read
    just before the run's Zenoh session closes (its threads end with it).
    With a recorder, ``recorder_startup_s`` is the CPU it spent before the
    modules started (interpreter, imports, subscribing: nothing per message)
    and ``recorder_us`` its CPU per message from then until it has written
    what it received (its own process, read from /proc: the modules' CPU,
    which changes when the recorder slows the star, stays out of it).
    """
    with tempfile.TemporaryDirectory() as tmp:
        run_dir = Path(tmp)
        interceptor = load_interceptor(policy, spec) if policy is not None else None
        options = RunOptions(mode=mode, params=params, run_dir=run_dir, interceptor=interceptor,
                             record=run_dir / "bench.mcap" if record else None, time_limit=timeout)
        sink = run_dir / "sink.json"
        threads0, at_end = thread_cpu(), {}
        recorder_cpu: list[float | None] = []  # at the modules' start, once the recorder has caught up

        def started(run: RunView) -> None:
            pid = run.recorder_pid
            recorder_cpu.append(process_cpu(pid) if pid is not None else None)

        def sink_done(run: RunView) -> str | None:
            if not sink.exists():
                return None
            at_end.update(thread_cpu())
            pid = run.recorder_pid
            if pid is not None:
                recorder_cpu.append(settled_cpu(pid))
            return "sink done"

        tool0, children0 = cpu_seconds(resource.RUSAGE_SELF), cpu_seconds(resource.RUSAGE_CHILDREN)
        outcome = run_session(spec, options, stop_when=sink_done, on_start=started)
        result = dict(wait_result(sink, timeout))
        # Children: the recorder (and the modules, which are the same in every row).
        tool, children = cpu_seconds(resource.RUSAGE_SELF) - tool0, cpu_seconds(resource.RUSAGE_CHILDREN) - children0
        per = 1e6 / max(1, result["received"])
        result["tool_cpu_us"] = tool * per
        result["children_cpu_us"] = children * per
        result["tool_threads_us"] = {kind: (seconds - threads0.get(kind, 0.0)) * per
                                     for kind, seconds in sorted(at_end.items())}
        result["recorder_startup_s"] = recorder_cpu[0] if recorder_cpu else None
        if len(recorder_cpu) == 2 and None not in recorder_cpu:
            result["recorder_us"] = (recorder_cpu[1] - recorder_cpu[0]) * per  # type: ignore[operator]
        return result, outcome.recorded


def fmt_threads(r: dict) -> str:
    """The tool's CPU per message by thread kind (Python threads; Zenoh's receiving and sending threads)."""
    return ", ".join(f"{kind} {us:.1f}" for kind, us in r["tool_threads_us"].items() if us >= 0.05) or "n/a"


def fmt_rate(r: dict) -> str:
    return f"{r['rate']:9,.0f} msg/s ({r['received']:,} received)"


def fmt_cpu(r: dict) -> str:
    return f"tool CPU {r['tool_cpu_us']:6.1f} µs/msg, children {r['children_cpu_us']:6.1f} µs/msg"


def throughput(size: int, count: int) -> None:
    params = {"size": str(size), "count": str(count), "rate": "0", "latency": ""}
    direct = run_direct(params)
    star, _ = run_tool(params, "star", record=False)
    star_rec, recorded = run_tool(params, "star", record=True)
    print(f"\nthroughput, {size} B messages, {count:,} sent")
    print(f"  direct pub → sub     {fmt_rate(direct)}")
    print(f"  star                 {fmt_rate(star)}   ratio {star['rate'] / direct['rate']:.2f}× direct")
    print(f"  star + recorder      {fmt_rate(star_rec)}   ratio {star_rec['rate'] / direct['rate']:.2f}× direct")
    print(f"  loss: sent {count:,}, delivered {star_rec['received']:,}, recorded {recorded.get('data', 0):,}")
    # Children: the modules and the recorder. Their difference counts the recorder's start-up and
    # whatever the modules spend differently when the recorder slows the star (an earlier figure).
    children_diff = star_rec["children_cpu_us"] - star["children_cpu_us"]
    recorder_us = star_rec.get("recorder_us")
    if recorder_us:
        print(f"  recorder CPU {recorder_us:.1f} µs/msg while recording (its own process; start-up "
              f"{star_rec['recorder_startup_s']:.2f} s CPU apart): alone it could sustain "
              f"{1e6 / recorder_us:,.0f} msg/s  [children's difference: {children_diff:.1f} µs/msg]")


def latency(count: int) -> None:
    params = {"size": "200", "count": str(count), "rate": "1000", "latency": "--latency"}
    direct = run_direct(params)
    star, _ = run_tool(params, "star", record=False)
    star_rec, _ = run_tool(params, "star", record=True)
    passive, _ = run_tool(params, "passive", record=False)
    passive_rec, _ = run_tool(params, "passive", record=True)
    print(f"\nlatency at 1 kHz, 200 B, {count:,} messages (one way, µs)")
    rows = [("direct", direct), ("star", star), ("star + recorder", star_rec),
            ("passive observer", passive), ("passive + recorder", passive_rec)]
    for name, r in rows:
        print(f"  {name:20} p50 {r['p50_us']:8.1f}   p99 {r['p99_us']:8.1f}")
    print(f"  star added p50: {(star['p50_us'] - direct['p50_us']) / 1000:.3f} ms; "
          f"star p99 / direct p99: {star['p99_us'] / direct['p99_us']:.2f}×")
    print(f"  passive + recorder vs direct: p50 {passive_rec['p50_us'] / direct['p50_us']:.2f}×, "
          f"p99 {passive_rec['p99_us'] / direct['p99_us']:.2f}×")


PAIRS = 3  # passthrough and mutated runs, interleaved: a lone passthrough rate varies by up to 2× (measured)


def interception(count: int) -> None:
    params = {"size": "200", "count": str(count), "rate": "0", "latency": ""}
    pairs = []
    for _ in range(PAIRS):
        pairs.append((run_tool(params, "star", record=False)[0],
                      run_tool(params, "star", record=False, policy=SET_POLICY)[0]))
    plain_rec, _ = run_tool(params, "star", record=True)
    mutated_rec, recorded = run_tool(params, "star", record=True, policy=SET_POLICY)
    print(f"\ninterception throughput, 200 B JSON, {count:,} sent; {PAIRS} pairs of runs, interleaved")
    for plain, mutated in pairs:
        print(f"  star passthrough     {fmt_rate(plain)}   {fmt_cpu(plain)}")
        print(f"  star + set on every  {fmt_rate(mutated)}   {fmt_cpu(mutated)}   "
              f"ratio {mutated['rate'] / plain['rate']:.2f}×")
    print(f"  passthrough + recorder {fmt_rate(plain_rec)}   {fmt_cpu(plain_rec)}")
    print(f"  set + recorder         {fmt_rate(mutated_rec)}   {fmt_cpu(mutated_rec)}   "
          f"ratio {mutated_rec['rate'] / plain_rec['rate']:.2f}× (both recorded)")
    ratios = sorted(m["rate"] / p["rate"] for p, m in pairs)
    plain, mutated = next((p, m) for p, m in pairs if m["rate"] / p["rate"] == ratios[PAIRS // 2])  # median pair
    print(f"  ratio (median pair) {ratios[PAIRS // 2]:.2f}× passthrough (all: {', '.join(f'{r:.2f}' for r in ratios)}); "
          f"mutated rates {', '.join(format(m['rate'], ',.0f') for _, m in pairs)} msg/s; with the recorder "
          f"{mutated_rec['rate'] / plain['rate']:.2f}× that pair's passthrough; tool CPU "
          f"{mutated['tool_cpu_us'] / plain['tool_cpu_us']:.2f}× passthrough's")
    print(f"  loss with set + recorder: sent {count:,}, delivered {mutated_rec['received']:,}, "
          f"recorded {recorded.get('data', 0):,}")
    if mutated_rec.get("recorder_us"):
        print(f"  recorder CPU with set on every message: {mutated_rec['recorder_us']:.1f} µs/msg "
              f"(original, delivery and event per message; its own process)")
    print("  tool CPU by thread kind, µs/msg (python: forwarders, engine, puts; rx/tx: Zenoh's own):")
    for name, r in (("passthrough", plain), ("set on every", mutated), ("+ recorder", mutated_rec)):
        print(f"    {name:14} {fmt_threads(r)}")
    lat = {"size": "200", "count": str(count // 20), "rate": "1000", "latency": "--latency"}
    plain_l, _ = run_tool(lat, "star", record=False)
    mutated_l, _ = run_tool(lat, "star", record=False, policy=SET_POLICY)
    monitored_l, _ = run_tool(lat, "star", record=False, spec=MONITORED)
    print("latency at 1 kHz (µs)   p50      p99")
    for name, r in (("star", plain_l), ("star + set", mutated_l), ("star + monitors", monitored_l)):
        print(f"  {name:18} {r['p50_us']:8.1f} {r['p99_us']:8.1f}")
    print(f"  added by mutation: p50 {(mutated_l['p50_us'] - plain_l['p50_us']) / 1000:.3f} ms; "
          f"online monitors (bound + expression): p50 {monitored_l['p50_us'] / plain_l['p50_us']:.2f}×, "
          f"p99 {monitored_l['p99_us'] / plain_l['p99_us']:.2f}× star")


def large(count: int) -> None:
    """Point-cloud sized messages (1 MB) at 30 Hz: the latency star and recorder add, and any loss."""
    params = {"size": str(1_000_000), "count": str(count), "rate": "30", "latency": "--latency"}
    direct = run_direct(params)
    star, _ = run_tool(params, "star", record=False)
    star_rec, recorded = run_tool(params, "star", record=True)
    print(f"\n1 MB messages at 30 Hz, {count:,} sent (one way, ms; the sink parses each message in all rows)")
    for name, r in (("direct", direct), ("star", star), ("star + recorder", star_rec)):
        print(f"  {name:18} p50 {r['p50_us'] / 1000:7.2f}   p99 {r['p99_us'] / 1000:7.2f}   "
              f"received {r['received']:,}")
    print(f"  added by the star: p50 {(star['p50_us'] - direct['p50_us']) / 1000:.2f} ms, "
          f"p99 {(star['p99_us'] - direct['p99_us']) / 1000:.2f} ms; with the recorder: "
          f"p50 {(star_rec['p50_us'] - direct['p50_us']) / 1000:.2f} ms, "
          f"p99 {(star_rec['p99_us'] - direct['p99_us']) / 1000:.2f} ms")
    print(f"  loss: sent {count:,}, delivered {star_rec['received']:,}, recorded {recorded.get('data', 0):,}; "
          f"recorder + modules CPU {star_rec['children_cpu_us'] / 1000:.2f} ms/msg "
          f"(modules alone {star['children_cpu_us'] / 1000:.2f})")


SECTIONS = ("throughput", "latency", "interception", "large")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer messages (a smoke run)")
    ap.add_argument("--only", choices=SECTIONS, action="append",
                    help="run only these sections (default: all)")
    args = ap.parse_args()
    scale = 0.1 if args.quick else 1.0
    wanted = args.only or SECTIONS
    if "throughput" in wanted:
        throughput(200, int(100_000 * scale))
        throughput(20_000, int(20_000 * scale))
    if "latency" in wanted:
        latency(int(5_000 * scale))
    if "interception" in wanted:
        interception(int(200_000 * scale))
    if "large" in wanted:
        large(max(30, int(300 * scale)))


if __name__ == "__main__":
    main()
