"""amr_common: the shared layer every amr package builds on (floor 1).

It imports no other amr package; whole programs built on it (Foxglove bridge, map publisher,
MCAP recorder, graph introspection) live in amr_tools. Its modules, by seam:

- amr_common.ros: ROS plumbing (lifecycle nodes and their manager, the executables' main, QoS,
  TF, message conversions, local graph isolation, the message_filters drop-in, typed
  parameters, /map messages).
- amr_common.plugins: the plug-in contract (the links' interfaces, the MODULE:CLASS loader and
  its overrides, what counts as a failed link, parameter tables).
- amr_common.world: worlds and maps (World and its files, Nav2 map files, occupancy and
  coverage grids, rasters, ray casting, the bundled worlds/).
- amr_common.sensors: sensor models (the LiDARs' datasheet bands, which readings are returns,
  de-skewing, range calibration).
- at the top, what every floor uses: geometry (angles, quaternions, poses), jit (the one
  numba-or-Python switch), robot (the TurtleBot3 Burger's constants and kinematics),
  navigation_behaviour (the chain's rules), pose_history, python_logging and stop_flag.

No module re-exports another's names: import from the module that defines them.
"""
