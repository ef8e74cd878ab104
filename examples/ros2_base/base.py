"""Kinematic base node: integrates the latest /cmd_vel (unicycle model) at 50 Hz, publishes nav_msgs/msg/Odometry.

Its speed limit reads `if abs(v) > MAX_SPEED` — a NaN command passes it and
the odometry turns NaN for good: the kind of bug astaa-deft's interception finds.
"""

import math
import os
import threading
import time

import numpy as np

from common import router_address, stop_event, use_local_definitions

RATE_HZ = 50.0
MAX_SPEED = 1.0  # m/s
MAX_TURN = 1.5  # rad/s

stop = stop_event()
use_local_definitions()
from zenoh_ros2_sdk import ROS2Publisher, ROS2Subscriber  # noqa: E402

lock = threading.Lock()
command = {"v": 0.0, "w": 0.0}


def on_cmd_vel(msg) -> None:
    v, w = msg.linear.x, msg.angular.z
    if abs(v) > MAX_SPEED:
        v = math.copysign(MAX_SPEED, v)
    if abs(w) > MAX_TURN:
        w = math.copysign(MAX_TURN, w)
    with lock:
        command["v"], command["w"] = v, w


ip, port = router_address()
odom = ROS2Publisher(topic="/odom", msg_type="nav_msgs/msg/Odometry", node_name="base", router_ip=ip,
                     router_port=port)
cmd_vel = ROS2Subscriber(topic="/cmd_vel", msg_type="geometry_msgs/msg/Twist", callback=on_cmd_vel,
                         node_name="base", router_ip=ip, router_port=port)
T = odom.session_mgr.store.types
print("base: subscribed to /cmd_vel, publishing /odom", flush=True)

x = y = yaw = 0.0
dt = 1.0 / RATE_HZ
while not stop.wait(dt):
    with lock:
        v, w = command["v"], command["w"]
    x += v * math.cos(yaw) * dt
    y += v * math.sin(yaw) * dt
    yaw += w * dt
    now = time.time()
    odom.publish(
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=int(now),
                                                                             nanosec=int(now % 1 * 1e9)),
                                        frame_id="odom"),
        child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                              w=math.cos(yaw / 2))),
            covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=v, y=0.0, z=0.0),
                                               angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=w)),
            covariance=np.zeros(36)))
cmd_vel.close()
odom.close()
os._exit(0)
