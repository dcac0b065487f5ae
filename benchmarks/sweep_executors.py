"""The sweep executors side by side: the same bench with ``--executor local`` and
``--executor dask`` (a LocalCluster made for the bench), alternately, ``--repeat`` times each.

Each bench is the command a user types (``ldhp-tamp bench SCENARIO... --seeds N --jobs J
--fresh -q --out DIR``), timed from outside: process start, cluster start and stop
included. Printed per executor: the command's wall time per repeat and its median, the
median over runs of ``wall_s`` (a run's wall time seen by the executor, the cell's process
start-up included) and of ``time_total_s`` (the solver's own time), and the statuses.

Run::

    .venv/bin/python benchmarks/sweep_executors.py
    .venv/bin/python benchmarks/sweep_executors.py --scenarios scenarios/example_pick.toml --seeds 4 --repeat 3
"""

from __future__ import annotations

import argparse
import csv
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
CLI = ROOT / ".venv" / "bin" / "ldhp-tamp"
SCENARIOS = ["scenarios/example_pick.toml", "scenarios/cmgmp_peg_in_hole.toml"]


def bench_once(executor: str, args: argparse.Namespace, out: Path) -> tuple[float, list[dict[str, str]]]:
    cmd = [str(CLI), "bench", *args.scenarios, "--seeds", str(args.seeds), "--jobs", str(args.jobs),
           "--executor", executor, "--out", str(out), "--fresh", "-q"]
    if not args.simulate:
        cmd.append("--no-simulate")
    start = time.perf_counter()
    subprocess.run(cmd, cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    with (out / "runs.csv").open(encoding="utf-8") as f:
        return wall, list(csv.DictReader(f))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", nargs="+", default=SCENARIOS)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--no-simulate", dest="simulate", action="store_false")
    args = parser.parse_args(argv)
    walls: dict[str, list[float]] = {"local": [], "dask": []}
    rows: dict[str, list[dict[str, str]]] = {"local": [], "dask": []}
    with tempfile.TemporaryDirectory(prefix="ldhp-sweep-bench-") as tmp:
        for i in range(args.repeat):
            for executor in walls:
                wall, got = bench_once(executor, args, Path(tmp) / f"{executor}-{i}")
                walls[executor].append(wall)
                rows[executor] += got
                print(f"repeat {i + 1}: {executor}: {wall:.1f} s", file=sys.stderr, flush=True)
    print(f"{len(args.scenarios)} scenario(s) x {args.seeds} seed(s), --jobs {args.jobs}, "
          f"simulate {args.simulate}, {args.repeat} repeat(s) per executor")
    print("| executor | command wall (s), each | median | median run wall_s | median time_total_s | statuses |")
    print("| --- | --- | ---: | ---: | ---: | --- |")
    for executor, ws in walls.items():
        rs = rows[executor]
        run_wall = statistics.median(float(r["wall_s"]) for r in rs)
        solved = [float(r["time_total_s"]) for r in rs if r["time_total_s"]]
        total = f"{statistics.median(solved):.2f}" if solved else "-"
        statuses = ", ".join(f"{n} {s}" for s, n in sorted(Counter(r["status"] for r in rs).items()))
        print(f"| {executor} | {', '.join(f'{w:.1f}' for w in ws)} | {statistics.median(ws):.1f} "
              f"| {run_wall:.2f} | {total} | {statuses} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
