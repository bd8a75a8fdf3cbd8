"""amr_sim: a pymunk TurtleBot3 Burger simulator. READ amr_sim/CONTRACT.md (API + working rules)."""
