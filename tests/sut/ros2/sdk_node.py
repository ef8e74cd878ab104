"""A ROS 2 node written with zenoh-ros2-sdk (a client no one here wrote); imports nothing from astaa-deft.

talker:   publishes geometry_msgs/msg/Twist on TOPIC (linear.x = 0.1 * i, angular.z = 0.5)
          and writes each payload and attachment it put, as hex JSON lines, to OUT.
listener: subscribes to TOPIC through the SDK (which decodes with its own typestore)
          and writes what the SDK decoded to OUT; a raw Zenoh subscriber on the
          SDK's own key writes the exact payload and attachment to OUT.raw.
          With --graph it also writes, as JSON lines to OUT.graph, what it sees
          of the ROS 2 graph: the SDK's own `get_topic_info` (verbose) and the
          keys a raw liveliness get on `@ros2_lv/<domain>/**` returns.
server:   serves SERVICE (example_interfaces/srv/AddTwoInts, definitions given
          inline) with sum = a + b; writes each request it served to OUT.
client:   waits until the SDK's `get_service_info` sees a server of SERVICE,
          then calls it --count times (a = i, b = 100) and writes each
          response (or "none") to OUT.
The talker and the server also write their session id (zid) to OUT.zid.

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
ap.add_argument("role", choices=("talker", "listener", "server", "client"))
ap.add_argument("--service", default="/add_two_ints")
ap.add_argument("--graph", action="store_true")
ap.add_argument("--topic", default="/cmd_vel")
ap.add_argument("--messages", required=True, help="directory of <pkg>/msg/<Name>.msg files")
ap.add_argument("--out", required=True)
ap.add_argument("--count", type=int, default=40)
ap.add_argument("--rate", type=float, default=50.0)
ap.add_argument("--start-delay", type=float, default=1.0)
ap.add_argument("--node", default=None)
ap.add_argument("--expect", type=int, default=0,
                help="listener: exit once this many messages arrived, decoded and raw (0: run until stopped)")
args = ap.parse_args()

stop = threading.Event()
signal.signal(signal.SIGTERM, lambda *_: stop.set())
signal.signal(signal.SIGINT, lambda *_: stop.set())

from zenoh_ros2_sdk import (  # noqa: E402
    ROS2Publisher, ROS2ServiceClient, ROS2ServiceServer, ROS2Subscriber, get_registry, get_service_info, get_topic_info,
)

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
ADD_TWO_INTS = "example_interfaces/srv/AddTwoInts"
REQUEST, RESPONSE = "int64 a\nint64 b", "int64 sum"
out = open(args.out, "w", buffering=1)  # noqa: SIM115 (open for the whole run)


def write_zid(session_mgr):
    with open(args.out + ".zid", "w") as fh:
        fh.write(session_mgr.session_id + "\n")


def watch_graph(session_mgr):
    """Every 0.3 s until stopped: the topic's endpoints by the SDK's graph API, and the raw tokens."""
    graph = open(args.out + ".graph", "w", buffering=1)  # noqa: SIM115
    while not stop.wait(0.3):
        info = get_topic_info(args.topic, router_ip=router_ip, router_port=router_port, verbose=True, timeout=0.5)
        tokens = sorted(str(reply.ok.key_expr) for reply in session_mgr.liveliness.get("@ros2_lv/0/**", timeout=0.5)
                        if reply.ok is not None)
        graph.write(json.dumps({
            "publishers": [p.node_name for p in info.publishers] if info else [],
            "subscribers": [s.node_name for s in info.subscribers] if info else [],
            "tokens": tokens}) + "\n")

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
    write_zid(publisher.session_mgr)
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
elif args.role == "server":
    def add(request):
        out.write(json.dumps({"a": int(request.a), "b": int(request.b)}) + "\n")
        return server.response_msg_class(sum=int(request.a) + int(request.b))

    server = ROS2ServiceServer(args.service, ADD_TWO_INTS, callback=add, request_definition=REQUEST,
                               response_definition=RESPONSE, node_name=args.node or "adder",
                               router_ip=router_ip, router_port=router_port)
    write_zid(server.session_mgr)
    print(f"server: serving {server.keyexpr}", flush=True)
    stop.wait()
    server.close()
elif args.role == "client":
    client = ROS2ServiceClient(args.service, ADD_TWO_INTS, request_definition=REQUEST, response_definition=RESPONSE,
                               node_name=args.node or "asker", router_ip=router_ip, router_port=router_port,
                               timeout=5.0)
    print(f"client: calling {client.keyexpr}", flush=True)
    deadline = time.monotonic() + 20
    while not stop.is_set() and time.monotonic() < deadline:  # as a ROS 2 client's wait_for_service
        info = get_service_info(args.service, router_ip=router_ip, router_port=router_port, timeout=0.5)
        if info is not None and info.server_count > 0:
            break
        stop.wait(0.2)
    print("client: service seen" if not stop.is_set() and time.monotonic() < deadline else "client: no service",
          flush=True)
    for i in range(args.count):
        if stop.is_set():
            break
        response = client.call(a=i, b=100)
        out.write(json.dumps({"a": i, "sum": None if response is None else int(response.sum)}) + "\n")
    print("client: done", flush=True)
    stop.wait()
    client.close()
else:
    raw = open(args.out + ".raw", "w", buffering=1)  # noqa: SIM115

    arrived = {"decoded": 0, "raw": 0}
    counting = threading.Lock()

    def count(kind):
        with counting:
            arrived[kind] += 1
            if args.expect and min(arrived.values()) >= args.expect:
                stop.set()  # the run's end: every expected message has arrived

    def on_message(msg):
        out.write(json.dumps({"linear": [msg.linear.x, msg.linear.y, msg.linear.z],
                              "angular": [msg.angular.x, msg.angular.y, msg.angular.z]}) + "\n")
        count("decoded")

    subscriber = ROS2Subscriber(topic=args.topic, msg_type=TWIST, callback=on_message,
                                node_name=args.node or "base", router_ip=router_ip, router_port=router_port)

    def on_raw(sample):
        attachment = sample.attachment.to_bytes() if sample.attachment is not None else b""
        raw.write(json.dumps({"payload": sample.payload.to_bytes().hex(), "attachment": attachment.hex()}) + "\n")
        count("raw")

    raw_sub = subscriber.session_mgr.session.declare_subscriber(subscriber.keyexpr, on_raw)
    print(f"listener: subscribed to {subscriber.keyexpr}", flush=True)
    if args.graph:
        watch_graph(subscriber.session_mgr)
    stop.wait()
    raw_sub.undeclare()
    subscriber.close()
os._exit(0)  # the SDK's session threads are not daemons
