"""ROS 2 systems on rmw_zenoh: the graph from liveliness tokens, and `spec discover`.

The ROS 2 parts below this layer: message types, RIHS01 hashes and keys in
``spec.ros2_types`` / ``spec.ros2_section``, the CDR codec in ``codecs.cdr``,
the rmw_zenoh attachment in ``codecs.rmw_attachment``.
"""
