"""In-process cost of the interception engine per message.

    python benchmarks/bench_intercept_engine.py [--count N]

Feeds ~200-byte JSON messages (a header, 4 points, an enum, a string
array: the message docs/codecs.md measures) through ``Interceptor.on_message``
and prints µs/message and messages/s for:

* a channel no policy touches (the proxy would not even call the engine);
* an affected channel whose policy's window is closed (the common case
  during a run: a counter and a few comparisons);
* a ``set`` policy mutating one field of every message (decode, set, encode);
* the same with a wildcard path and a derive rule (time.jump_back reads the
  previous message);
* a ``set`` on a CBOR channel.

The live proxy throughput ratio (set-every-message vs passthrough, target
≥ 0.6×) is measured end to end by the proxy benchmark; this one isolates
what the engine adds. Asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import cbor2

from astaa_deft.io.codecs import get_codec
from astaa_deft.engine.intercept import Interceptor, load_dictionary, parse_testcase
from astaa_deft.engine.spec.loader import load_spec_text

SPEC = load_spec_text("""
name: bench_intercept
modules: [{name: planner, command: "true"}, {name: control, command: "true"}]
channels:
  - {name: traj, key: b/traj, producer: planner, consumers: [control], type: Trajectory}
  - {name: quiet, key: b/quiet, producer: planner, consumers: [control], type: Trajectory}
  - {name: traj_cbor, key: b/cbor, producer: planner, consumers: [control], type: Trajectory, encoding: cbor}
types:
  Header: {seq: uint64, stamp: time}
  Point: {x: float64, y: float64, v: float32}
  Trajectory:
    header: Header
    points: {array: Point}
    gear: {enum: [drive, reverse, park]}
    tags: string[]
""")
DICTIONARY = load_dictionary()


def message(seq: int) -> dict:
    return {"header": {"seq": seq, "stamp": 1700000000.0 + seq / 100},
            "points": [{"x": 1.5 * i, "y": -0.25 * i, "v": 12.0 + i} for i in range(4)],
            "gear": "drive", "tags": ["lane", "follow"]}


def interceptor(policy: str) -> Interceptor:
    xml = f'<testcase id="bench" seed="1"><description/>{policy}</testcase>'
    return Interceptor(parse_testcase(xml.encode(), "bench.xml", SPEC), SPEC, DICTIONARY)


FLOOR = "codec alone (no engine)"
SET_ONE = '<set><field path="points[0].v" value="dict:float.nan"/></set>'
CASES = {  # name -> (channel the messages arrive on, the test case's policy)
    "untouched channel": ("quiet", '<policy id="p"><channel>traj</channel><drop/></policy>'),
    "window closed": ("traj", f'<policy id="p"><channel>traj</channel><window from="1000000"/>{SET_ONE}</policy>'),
    "set 1 field, every message": ("traj", f'<policy id="p"><channel>traj</channel>{SET_ONE}</policy>'),
    "set [*] + derive rule": ("traj", (
        '<policy id="p"><channel>traj</channel><set><field path="points[*].v" value="dict:float.inf"/>'
        '<field path="header.stamp" value="dict:time.jump_back"/></set></policy>')),
    "set 1 field, CBOR": ("traj_cbor", f'<policy id="p"><channel>traj_cbor</channel>{SET_ONE}</policy>'),
}


def run_once(channel: str, policy: str, payloads: list[bytes]) -> float:
    """Seconds per message for one fresh engine over all payloads."""
    on_message = interceptor(policy).on_message
    consumers = ("control",)
    start = time.perf_counter()
    for i, payload in enumerate(payloads):
        on_message(channel, consumers, payload, i * 0.001)
    return (time.perf_counter() - start) / len(payloads)


def codec_floor(payloads: list[bytes]) -> float:
    """Seconds per message for the unavoidable part: decode, set one field, encode (no engine)."""
    codec = get_codec("json")
    start = time.perf_counter()
    for payload in payloads:
        decoded = codec.decode(payload)
        decoded["points"][0]["v"] = math.nan
        codec.encode(decoded)
    return (time.perf_counter() - start) / len(payloads)


def measure_all(count: int, rounds: int) -> dict[str, float]:
    """Best per case over ``rounds``, the cases interleaved so a busy moment hits them all alike."""
    json_payloads = [json.dumps(message(i), separators=(",", ":")).encode() for i in range(count)]
    cbor_payloads = [cbor2.dumps(message(i)) for i in range(count)]
    best = {name: math.inf for name in [*CASES, FLOOR]}
    for _ in range(rounds):
        for name, (channel, policy) in CASES.items():
            payloads = cbor_payloads if channel == "traj_cbor" else json_payloads
            best[name] = min(best[name], run_once(channel, policy, payloads))
        best[FLOOR] = min(best[FLOOR], codec_floor(json_payloads))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=20_000, help="messages per run")
    parser.add_argument("--rounds", type=int, default=5, help="runs per case; the best one counts")
    args = parser.parse_args()
    size = len(json.dumps(message(12345), separators=(",", ":")))
    print(f"messages: {size} B JSON, {args.count:,} per run, best of {args.rounds}")
    results = measure_all(args.count, args.rounds)
    for name, seconds in results.items():
        print(f"  {name:28s} {seconds * 1e6:7.2f} µs/message  {1 / seconds:12,.0f} messages/s")
    setting, floor = results["set 1 field, every message"], results[FLOOR]
    print(f"set-every-message: {setting * 1e6:.1f} µs per message, of which the codec (decode, set, "
          f"encode) {floor * 1e6:.1f} µs and the engine (selection, event, delivery) {(setting - floor) * 1e6:.1f} µs")


if __name__ == "__main__":
    main()
