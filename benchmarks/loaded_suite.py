"""The test suite on a busy machine: two CPU-bound processes beside ``pytest``.

CI shares a 2-core machine, so no test's verdict may depend on how busy it is (issue 15).
This starts two pure-Python busy loops (each bounded in time by ``--busy-limit``, and
killed when the suite ends), runs the README's test command from the repository root
beside them (``.venv/bin/python -m pytest -q``, plus any arguments given after ``--``),
and prints the failures, the summary (counted from a JUnit XML report: the project's
``addopts = "-q"`` and the command's ``-q`` silence pytest's own summary line) and the wall
time. Exit status: pytest's.

Run::

    .venv/bin/python benchmarks/loaded_suite.py
    .venv/bin/python benchmarks/loaded_suite.py -- tests/ldhp_tamp/test_budget.py tests/fuzz
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PYTHON = ROOT / ".venv" / "bin" / "python"
#: A pure-Python busy loop that stops by itself after argv[1] seconds.
BUSY = "import sys, time\nend = time.monotonic() + float(sys.argv[1])\nwhile time.monotonic() < end:\n    sum(range(1000))\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--busy", type=int, default=2, help="CPU-bound processes beside the suite (default 2)")
    parser.add_argument("--busy-limit", type=float, default=7200.0,
                        help="seconds after which a busy process stops by itself (default 7200)")
    parser.add_argument("pytest_args", nargs="*", help="after --: passed to pytest")
    args = parser.parse_args(argv)

    busy = [subprocess.Popen([sys.executable, "-c", BUSY, str(args.busy_limit)]) for _ in range(args.busy)]
    print(f"{len(busy)} busy processes: {', '.join(str(p.pid) for p in busy)}; load average "
          f"{os.getloadavg()[0]:.2f}", flush=True)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "junit.xml"
        try:
            run = subprocess.run([str(PYTHON), "-m", "pytest", "-q", "-rfE", f"--junitxml={report}",
                                  *args.pytest_args], cwd=ROOT, capture_output=True, text=True)
        finally:
            for p in busy:
                if p.poll() is None:
                    p.send_signal(signal.SIGKILL)
                p.wait()
        wall = time.perf_counter() - t0
        lines = run.stdout.strip().splitlines()
        print("\n".join(ln for ln in lines if ln.startswith(("FAILED", "ERROR"))))
        if report.is_file():
            suite = ET.parse(report).getroot()
            suite = suite if suite.tag == "testsuite" else suite.find("testsuite")
            n, failed, errors, skipped = (int(suite.get(k, 0)) for k in ("tests", "failures", "errors", "skipped"))
            print(f"pytest: {n - failed - errors - skipped} passed, {failed} failed, {errors} errors, "
                  f"{skipped} skipped in {float(suite.get('time', 0)):.1f} s")
        else:
            print(run.stdout.strip()[-2000:] + run.stderr.strip()[-2000:])
    print(f"wall time {wall:.1f} s beside {len(busy)} busy processes (pytest exit {run.returncode}); "
          f"load average at the end {os.getloadavg()[0]:.2f}")
    return run.returncode


if __name__ == "__main__":
    sys.exit(main())
