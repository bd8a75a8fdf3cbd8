"""amr_evaluation: the harness above the algorithm packages (floor 3).

Headless episodes that wire the simulator to controllers (episode), batch evaluation on all
cores (evaluation, evaluation_report) and pictures for lab reports (plot).
"""
