"""amr_common.ros: the ROS plumbing the nodes share (rclpy lives here, not in the algorithms).

- lifecycle_node: GuardedLifecycleNode, the base of every lifecycle node.
- lifecycle_manager: brings the lifecycle nodes up in order (`amr_lifecycle_manager`).
- node_runner: the main of every node executable (autostart, Ctrl-C).
- ros_env: a private ROS_DOMAIN_ID and loopback discovery for local graphs.
- qos: the QoS profiles of the project's topics.
- tf, map_odom_tf: transforms of planar poses; map -> odom out, the LiDAR's /tf_static in.
- ros_conversions: building and reading the messages the nodes exchange.
- message_filters + time_matching: the message_filters drop-in and its matching logic.
- parameters: typed ROS parameters from parameter tables (integers where doubles are due).
- map_messages: a world as /map and /map_markers.
"""
