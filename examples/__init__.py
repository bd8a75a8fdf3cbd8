"""Course-style implementations of the chain's links, each a few screens of plain Python.

Each implements one interface of amr_common.plugins.interfaces and runs in place of the project's
class through run_sim.py, evaluate.py and tune.py (docs/own-algorithm.md):
likelihood_mcl (--localizer), wavefront_planner (--planner), plain_pursuit (--follower),
odometry_mapper (--mapper, with --slam).
They import only the shared layer (amr_common), as a student's class would.
"""
