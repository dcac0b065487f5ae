"""An external planner for the tests of ``cmd:`` planners that writes garbage.

Usage: ``garbage_plan.py SCENARIO PLAN``."""

import sys

with open(sys.argv[2], "w", encoding="utf-8") as f:
    f.write("this is not a plan {")
