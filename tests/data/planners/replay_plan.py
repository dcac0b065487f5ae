"""An external planner for the tests of ``cmd:`` planners: replays a stored plan.

Usage: ``replay_plan.py STORED SCENARIO PLAN``: copies the plan file STORED to PLAN (the
scenario is not read)."""

import shutil
import sys

stored, _scenario, plan = sys.argv[1:4]
shutil.copyfile(stored, plan)
