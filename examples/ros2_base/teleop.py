"""Teleop node: geometry_msgs/msg/Twist on /cmd_vel at 20 Hz (accelerate to 0.8 m/s while turning)."""

import os
import time

from common import router_address, stop_event, use_local_definitions

RATE_HZ = 20.0

stop = stop_event()
use_local_definitions()
from zenoh_ros2_sdk import ROS2Publisher  # noqa: E402

ip, port = router_address()
cmd_vel = ROS2Publisher(topic="/cmd_vel", msg_type="geometry_msgs/msg/Twist", node_name="teleop",
                        router_ip=ip, router_port=port)
Vector3 = cmd_vel.session_mgr.store.types["geometry_msgs/msg/Vector3"]
print("teleop: publishing /cmd_vel", flush=True)
t0 = time.monotonic()
while not stop.wait(1.0 / RATE_HZ):
    t = time.monotonic() - t0
    cmd_vel.publish(linear=Vector3(x=min(0.8, 0.4 * t), y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=0.3))
cmd_vel.close()
os._exit(0)  # the SDK's session threads are not daemons
