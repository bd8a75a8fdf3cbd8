"""amr_common: the shared layer every amr package builds on (floor 1).

ROS plumbing (node_runner, ros_env, lifecycle_manager, message_filters + time_matching, qos,
ros_conversions, controller_loader), geometry (angles, quaternions), the
TurtleBot3 Burger's constants and kinematics (robot), the world map loader (world + worlds/) and
its geometry kernels (raycast), and the one numba-or-Python switch (jit). It imports no other amr
package; whole programs built on it (Foxglove bridge, map publisher, MCAP recorder, graph
introspection) live in amr_tools.
"""
