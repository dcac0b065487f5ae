"""Units and tolerances, in one place.

Units inside the package: millimetres, radians, kilograms, newtons. Files (scenarios,
plans) use degrees; conversion happens only at the I/O boundary (``ldhp_tamp``).

The planner is stricter than the plan validator: a plan made with the planner's
tolerances passes the validator's (``ldhp-plan/1``) 1 mm / 1 degree rules with margin.
"""

from __future__ import annotations

#: Two features closer than this (mm) are in contact (planner side).
CONTACT_TOL: float = 0.1

#: Overlap tolerance (mm) of the planner's checks, in the plan spec's sense (rule 3): two
#: bodies overlap when their intersection eroded by this much is non-empty. A thin strip
#: of overlap is thus tolerated up to twice this depth.
PENETRATION_TOL: float = 0.1

#: Overlap tolerance (mm) used when a sweep bisects for the exact parameter where a new
#: contact is made: much tighter than PENETRATION_TOL, because the erosion rule lets a
#: thin sliver at a vertex sink about twice its tolerance.
SWEEP_TOL: float = 1e-4

#: A Step-1 contact pose stops this far (mm) short of where the sweep is blocked: a sweep
#: ends where the overlap test starts to fail, i.e. already sunk into the solid by up to a
#: few SWEEP_TOL at a vertex, and a rotation about that vertex could then start inside
#: the solid and be blocked at once. Far below CONTACT_TOL: the pose still touches.
CONTACT_BACKOFF: float = 1e-3

#: Overlap tolerance (mm) between a candidate grasp's fingers (and palm) and the object
#: in the object frame: fingers that touch the object sit exactly on its boundary.
GRASP_OBJECT_TOL: float = 1e-3

#: Validator tolerances of the plan spec (``ldhp-plan/1``): contact and position (mm).
VALIDATE_TOL: float = 1.0

#: Validator angle tolerance of the plan spec (degrees).
VALIDATE_TOL_DEG: float = 1.0

#: Largest motion (mm) of any object vertex, finger centre or finger vertex, and largest
#: width change, between consecutive plan waypoints (plan spec rule 2).
MAX_WAYPOINT_STEP: float = 5.0

#: Waypoint spacing the planner aims for (mm): below MAX_WAYPOINT_STEP with margin.
WAYPOINT_STEP: float = 4.0

#: Quasi-static feasibility margin, in normalised wrench units (forces / (m g), moments /
#: (m g L)): a certificate whose margin is below this counts as infeasible.
FEASIBILITY_MARGIN: float = 1e-7

#: Gravity (m/s^2), pointing along world -y.
GRAVITY: float = 9.81

#: Numerical zero for geometric predicates (mm or mm^2).
EPS: float = 1e-9
