"""ROS 2 (CDR over rmw_zenoh keys) costs, measured in one run.

    python benchmarks/bench_ros2.py [--quick]

1. Codec cost per message: CDR decode / set one field / encode (rosbags plus
   the plain-data conversion) against JSON of the same plain data.
2. Bus: a CDR PointCloud2 source and sink (zenoh + rosbags only, rmw_zenoh
   keys and 33-byte attachments; latency from the attachment's source
   timestamp), wired directly (peer to peer), through the star, through the
   star rewriting one field of every message, and observed passively; 200 B
   and 100 kB messages. Prints figures and ratios; asserts nothing.
"""

from __future__ import annotations

import argparse
import base64
import time
from pathlib import Path

import numpy as np

from astaa_deft.io.codecs import get_codec
from astaa_deft.model.fields import set_field
from astaa_deft.engine.spec.loader import load_spec
from astaa_deft.io.ros2.types import shared_types

import bench_proxy  # the same direct and through-the-tool runs, on the ROS 2 bench spec

SUT = Path(__file__).parent / "sut" / "ros2"
SPEC = load_spec(SUT / "bench.yaml")
SET_POLICY = SUT / "set_every_message.xml"
KEY = SPEC.channel("points").key
RESULT_TIMEOUT = 180.0
STORE = shared_types().store
T = STORE.types


# ---------------------------------------------------------------- codec cost

def sample_messages() -> dict[str, tuple[str, bytes]]:
    vec = T["geometry_msgs/msg/Vector3"]
    twist = T["geometry_msgs/msg/Twist"](linear=vec(x=0.5, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.3))
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="odom")
    pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=1.0, y=2.0, z=0.0),
                                       orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0))
    odom = T["nav_msgs/msg/Odometry"](
        header=header, child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=np.zeros(36)))
    field = T["sensor_msgs/msg/PointField"](name="x", offset=0, datatype=7, count=1)
    cloud = T["sensor_msgs/msg/PointCloud2"](header=header, height=1, width=6250, fields=[field], is_bigendian=False,
                                             point_step=16, row_step=100_000, data=np.full(100_000, 7, np.uint8),
                                             is_dense=True)
    out = {}
    for label, type_name, msg, path in (("Twist", "geometry_msgs/msg/Twist", twist, "linear.x"),
                                        ("Odometry", "nav_msgs/msg/Odometry", odom, "twist.twist.linear.x"),
                                        ("PointCloud2 100 kB", "sensor_msgs/msg/PointCloud2", cloud, "is_dense")):
        out[label] = (type_name, bytes(STORE.serialize_cdr(msg, type_name)), path)
    return out


def per_call_us(fn, repeat: int) -> float:
    fn()
    t0 = time.perf_counter()
    for _ in range(repeat):
        fn()
    return (time.perf_counter() - t0) / repeat * 1e6


def codec_costs(repeat: int) -> None:
    print("\ncodec cost per message (µs): decode, set one field, encode; JSON of the same plain data")
    print(f"  {'message':20} {'bytes':>7} {'CDR dec':>8} {'set':>6} {'CDR enc':>8} {'CDR d+s+e':>10}"
          f" {'JSON bytes':>10} {'JSON d+s+e':>11} {'CDR/JSON':>9}")
    for label, (type_name, raw, path) in sample_messages().items():
        codec_row(label, type_name, raw, path, repeat)


def codec_row(label: str, type_name: str, raw: bytes, path: str, repeat: int) -> None:
    codec, json_codec = get_codec("cdr:" + type_name), get_codec("json")
    n = max(20, repeat // (50 if len(raw) > 10_000 else 1))
    message = codec.decode(raw)
    value = not message["is_dense"] if path == "is_dense" else -1.0
    dec = per_call_us(lambda: codec.decode(raw), n)
    setting = per_call_us(lambda: set_field(message, path, value), n)
    enc = per_call_us(lambda: codec.encode(message), n)

    def cdr_path() -> bytes:
        m = codec.decode(raw)
        set_field(m, path, value)
        return codec.encode(m)

    total = per_call_us(cdr_path, n)
    # The same plain data as JSON (byte arrays as base64 text, as the JSON codec carries them).
    as_json = {k: (base64.b64encode(v).decode() if isinstance(v, bytes) else v) for k, v in message.items()}
    json_raw = json_codec.encode(as_json)

    def json_path() -> bytes:
        m = json_codec.decode(json_raw)
        set_field(m, path, value)
        return json_codec.encode(m)

    total_json = per_call_us(json_path, n)
    print(f"  {label:20} {len(raw):7,} {dec:8.1f} {setting:6.1f} {enc:8.1f} {total:10.1f}"
          f" {len(json_raw):10,} {total_json:11.1f} {total / total_json:8.2f}×")


# ---------------------------------------------------------------- bus

def run_direct(params: dict[str, str]) -> dict:
    return bench_proxy.run_direct(params, spec=SPEC, sut=SUT, timeout=RESULT_TIMEOUT)


def run_tool(params: dict[str, str], mode: str, policy: Path | None = None) -> dict:
    result, _recorded = bench_proxy.run_tool(params, mode, False, spec=SPEC, policy=policy, timeout=RESULT_TIMEOUT)
    return result


def bus(size: int, count: int, rate: float) -> None:
    params = {"size": str(size), "count": str(count), "rate": str(rate), "key": KEY}
    rows = [("direct pub → sub", run_direct(params)), ("star", run_tool(params, "star")),
            ("star + set per msg", run_tool(params, "star", SET_POLICY)),
            ("passive observer", run_tool(params, "passive"))]
    what = "as fast as possible" if not rate else f"at {rate:g} Hz"
    print(f"\n{size:,} B CDR PointCloud2, {count:,} sent {what}")
    print(f"  {'path':20} {'msg/s':>9} {'received':>9} {'p50 µs':>9} {'p99 µs':>9}")
    direct = rows[0][1]
    for name, r in rows:
        print(f"  {name:20} {r['rate']:9,.0f} {r['received']:9,} {r['p50_us']:9.1f} {r['p99_us']:9.1f}")
    star = rows[1][1]
    print(f"  star / direct: throughput {star['rate'] / direct['rate']:.2f}×, "
          f"added p50 {(star['p50_us'] - direct['p50_us']) / 1000:.3f} ms, "
          f"p99 {star['p99_us'] / direct['p99_us']:.2f}×;"
          f" passive / direct throughput {rows[3][1]['rate'] / direct['rate']:.2f}×")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="fewer messages (a smoke run)")
    args = ap.parse_args()
    scale = 0.1 if args.quick else 1.0
    codec_costs(int(20_000 * scale))
    bus(200, int(50_000 * scale), 0)
    bus(100_000, int(5_000 * scale), 0)
    bus(200, int(3_000 * scale), 1000)
    bus(100_000, int(1_000 * scale), 100)


if __name__ == "__main__":
    main()
