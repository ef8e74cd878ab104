"""ROS 2-style benchmark publisher: one CDR sensor_msgs/PointCloud2 of SIZE bytes, COUNT times.

Publishes on an rmw_zenoh key with rmw_zenoh's 33-byte attachment (sequence,
source timestamp in ns, GID); the sink measures latency from that timestamp.
Uses zenoh and rosbags only (config from ZENOH_CONFIG).
"""

import argparse
import os
import signal
import struct
import threading
import time

import numpy as np
import zenoh
from rosbags.typesys import Stores, get_typestore

ap = argparse.ArgumentParser()
ap.add_argument("--key", required=True)
ap.add_argument("--size", type=int, default=200, help="total CDR payload size, bytes")
ap.add_argument("--count", type=int, default=10000)
ap.add_argument("--rate", type=float, default=0.0)
ap.add_argument("--start-delay", type=float, default=1.0)
args = ap.parse_args()

stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())

store = get_typestore(Stores.ROS2_JAZZY)
T = store.types


def cloud(data_size: int) -> bytes:
    header = T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="lidar")
    field = T["sensor_msgs/msg/PointField"](name="x", offset=0, datatype=7, count=1)
    msg = T["sensor_msgs/msg/PointCloud2"](header=header, height=1, width=max(1, data_size // 16), fields=[field],
                                           is_bigendian=False, point_step=16, row_step=data_size,
                                           data=np.full(data_size, 7, np.uint8), is_dense=True)
    return bytes(store.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2"))


overhead = len(cloud(0))
payload = cloud(max(0, args.size - overhead))
print(f"source: {len(payload)} B CDR payloads", flush=True)
gid = os.urandom(16)
session = zenoh.open(zenoh.Config.from_env())
pub = session.declare_publisher(args.key, congestion_control=zenoh.CongestionControl.BLOCK)
time.sleep(args.start_delay)
period = 1.0 / args.rate if args.rate else 0.0
next_t = time.monotonic()
head = struct.Struct("<qqB")
for i in range(args.count):
    if stop.is_set():
        break
    pub.put(payload, encoding=zenoh.Encoding("application/cdr"),
            attachment=head.pack(i, time.time_ns(), 16) + gid)
    if period:
        next_t += period
        delay = next_t - time.monotonic()
        if delay > 0:
            time.sleep(delay)
stop.wait()
session.close()
