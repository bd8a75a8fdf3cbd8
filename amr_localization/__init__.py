"""Monte Carlo localization of the Burger in a known maze.

Monte Carlo localization of the Burger in a known maze (algorithm without ROS, plus the
`particle_filter` lifecycle node). Imports only amr_common and amr_msgs.
"""
