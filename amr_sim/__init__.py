"""amr_sim: a pymunk TurtleBot3 Burger simulator (robot, LiDAR, sensor profiles) and its node.

Python API without ROS: `amr_sim.simulator.Simulator(world, start, dt, profile, seed).step(v, w)`
on a `amr_common.world.world.World`; the ROS node is `amr_sim.simulator_node` (`amr_simulator`).
It imports only amr_common: never a controller, filter or planner.
"""
