"""An external planner for the tests of ``cmd:`` planners that never finishes: it sleeps,
writing its pid to PIDFILE first (so the test can see it was stopped).

Usage: ``sleep_plan.py PIDFILE SCENARIO PLAN``."""

import os
import sys
import time

with open(sys.argv[1], "w", encoding="utf-8") as f:
    f.write(str(os.getpid()))
while True:
    time.sleep(1)
