"""ROS 2's own formats as the tool reads them: .msg type definitions and rmw_zenoh's liveliness tokens."""
