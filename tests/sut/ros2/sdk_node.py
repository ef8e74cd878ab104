"""A ROS 2 node written with zenoh-ros2-sdk (a client no one here wrote); imports nothing from astaa-deft.

talker:   publishes geometry_msgs/msg/Twist on TOPIC (linear.x = 0.1 * i, angular.z = 0.5)
          and writes each payload and attachment it put, as hex JSON lines, to OUT.
listener: subscribes to TOPIC through the SDK (which decodes with its own typestore)
          and writes what the SDK decoded to OUT; a raw Zenoh subscriber on the
          SDK's own key writes the exact payload and attachment to OUT.raw.

Like an rmw_zenoh node it reads ZENOH_SESSION_CONFIG_URI (the SDK does).
The SDK then overwrites connect endpoints with its router_ip/router_port
arguments, so the node passes the endpoint its config file names. Message
definitions come from --messages (a local <pkg>/msg/<Name>.msg tree): the SDK
would otherwise try to download them.
"""

import argparse
import json
import os
import signal
import sys
import threading
import time

ap = argparse.ArgumentParser()
ap.add_argument("role", choices=("talker", "listener"))
ap.add_argument("--topic", default="/cmd_vel")
ap.add_argument("--messages", required=True, help="directory of <pkg>/msg/<Name>.msg files")
ap.add_argument("--out", required=True)
ap.add_argument("--count", type=int, default=40)
ap.add_argument("--rate", type=float, default=50.0)
ap.add_argument("--start-delay", type=float, default=1.0)
ap.add_argument("--node", default=None)
args = ap.parse_args()

stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
signal.signal(signal.SIGINT, lambda *_: stop.set())

from zenoh_ros2_sdk import ROS2Publisher, ROS2Subscriber, get_registry  # noqa: E402

get_registry(args.messages)  # the first call fixes where the SDK looks for definitions

router_ip, router_port = "127.0.0.1", 7447
config_uri = os.environ.get("ZENOH_SESSION_CONFIG_URI", "")
if config_uri:
    with open(config_uri) as fh:
        endpoints = json.load(fh).get("connect", {}).get("endpoints", [])
    if endpoints:  # "tcp/127.0.0.1:PORT"
        router_ip, _, port = endpoints[0].split("/", 1)[1].rpartition(":")
        router_port = int(port)
else:
    sys.exit("sdk_node: no ZENOH_SESSION_CONFIG_URI (run me under astaa-deft)")

TWIST = "geometry_msgs/msg/Twist"
out = open(args.out, "w", buffering=1)  # noqa: SIM115 (open for the whole run)

if args.role == "talker":
    publisher = ROS2Publisher(topic=args.topic, msg_type=TWIST, node_name=args.node or "teleop",
                              router_ip=router_ip, router_port=router_port)

    class RecordingPublisher:
        """Writes down exactly what the SDK hands to Zenoh, then passes it on."""

        def __init__(self, inner):
            self.inner = inner

        def put(self, payload, **options):
            attachment = options.get("attachment") or b""
            out.write(json.dumps({"payload": bytes(payload).hex(), "attachment": bytes(attachment).hex()}) + "\n")
            self.inner.put(payload, **options)

        def undeclare(self):
            self.inner.undeclare()

    publisher.pub = RecordingPublisher(publisher.pub)
    vector = publisher.session_mgr.store.types["geometry_msgs/msg/Vector3"]
    print(f"talker: publishing on {publisher.keyexpr}", flush=True)
    time.sleep(args.start_delay)
    for i in range(args.count):
        if stop.is_set():
            break
        publisher.publish(linear=vector(x=0.1 * i, y=0.0, z=0.0), angular=vector(x=0.0, y=0.0, z=0.5))
        time.sleep(1.0 / args.rate)
    print("talker: done", flush=True)
    stop.wait()
    publisher.close()
else:
    raw = open(args.out + ".raw", "w", buffering=1)  # noqa: SIM115

    def on_message(msg):
        out.write(json.dumps({"linear": [msg.linear.x, msg.linear.y, msg.linear.z],
                              "angular": [msg.angular.x, msg.angular.y, msg.angular.z]}) + "\n")

    subscriber = ROS2Subscriber(topic=args.topic, msg_type=TWIST, callback=on_message,
                                node_name=args.node or "base", router_ip=router_ip, router_port=router_port)

    def on_raw(sample):
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else b""
        raw.write(json.dumps({"payload": sample.payload.to_bytes().hex(), "attachment": attachment.hex()}) + "\n")

    raw_sub = subscriber.session_mgr.session.declare_subscriber(subscriber.keyexpr, on_raw)
    print(f"listener: subscribed to {subscriber.keyexpr}", flush=True)
    stop.wait()
    raw_sub.undeclare()
    subscriber.close()
os._exit(0)  # the SDK's session threads are not daemons
