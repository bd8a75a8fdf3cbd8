"""amr_sim: a pymunk TurtleBot3 Burger simulator (world, robot, LiDAR, profiles) and its node.

Python API without ROS: `amr_sim.world.World.load(name_or_path)`,
`amr_sim.simulator.Simulator(world, start, dt, profile, seed).step(v, w)`,
`amr_sim.episode.run_episode(...)`; the ROS node is `amr_sim.simulator_node` (`amr_simulator`).
"""
