"""The geometric backend of ldhp-tamp: shapes, contacts, collision, mechanics, grasps.

Pure functions over immutable values, vectorised with numpy where hot. This package never
imports ``ldhp_tamp`` or anything PDDL. Units: mm, radians, kg (see :mod:`geometry.tolerances`).
"""
