"""Baseline planners of other families, on the same geometric backend and checks as LDHP.

- :mod:`ldhp_tamp.baselines.contact_rrt`: ``contact-rrt``, an RRT over object poses whose
  extensions follow enumerated environment contact modes (after CMGMP-2D, Cheng et al.
  2021), registered in :data:`ldhp_tamp.planners.PLANNERS` when imported.
"""
