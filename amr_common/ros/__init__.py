"""ROS plumbing of amr_common."""
