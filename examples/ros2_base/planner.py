"""Planner node: on each /odom (nav_msgs/msg/Odometry), a one-second nav_msgs/msg/Path on /plan.

The planning itself is path_planner.plan, which the spec's DeFT replay
factory (path_planner:PathPlanner) runs on the same inputs.
"""

import os

from common import router_address, stop_event, use_local_definitions
from path_planner import plan

stop = stop_event()
use_local_definitions()
from zenoh_ros2_sdk import ROS2Publisher, ROS2Subscriber  # noqa: E402

ip, port = router_address()
path = ROS2Publisher(topic="/plan", msg_type="nav_msgs/msg/Path", node_name="planner", router_ip=ip,
                     router_port=port)
T = path.session_mgr.store.types
state: dict = {}


def on_odom(msg) -> None:
    pose, twist, stamp = msg.pose.pose, msg.twist.twist, msg.header.stamp
    poses = plan(state, pose.position.x, pose.position.y, pose.orientation.z, pose.orientation.w,
                 twist.linear.x, twist.angular.z, stamp.sec, stamp.nanosec)

    def header(sec, nanosec):
        return T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=int(sec), nanosec=int(nanosec)),
                                        frame_id="odom")

    path.publish(header=header(stamp.sec, stamp.nanosec), poses=[
        T["geometry_msgs/msg/PoseStamped"](
            header=header(sec, nanosec),
            pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=px, y=py, z=0.0),
                                             orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=qz, w=qw)))
        for px, py, qz, qw, sec, nanosec in poses])


odom = ROS2Subscriber(topic="/odom", msg_type="nav_msgs/msg/Odometry", callback=on_odom, node_name="planner",
                      router_ip=ip, router_port=port)
print("planner: subscribed to /odom, publishing /plan", flush=True)
stop.wait()
odom.close()
path.close()
os._exit(0)
