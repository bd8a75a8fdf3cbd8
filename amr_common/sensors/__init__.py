"""amr_common.sensors: sensor models the simulator and the algorithms share (no ROS import).

- lidar_models: the TurtleBot3's LiDARs (LDS-01, LDS-02) as their datasheets describe them.
- scan_returns: which scan readings are returns, the one rule.
- scan_deskew: each ray moved to the LiDAR's pose at the stamp, from the odometry.
- range_calibration: a LiDAR unit's range correction, measured against walls.
"""
