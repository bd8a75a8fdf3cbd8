"""Online 2D graph SLAM: the map a robot has not been given, from its scans and odometry.

The Mapper (algorithm without ROS; amr_mapping.mapper) and its parts. Imports only amr_common
(and gtsam, numpy, numba).
"""
