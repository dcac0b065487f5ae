"""Paired before/after timing of two checkouts, solve by solve: is a change faster?

Two long-lived worker processes, one per source tree (``--a`` and ``--b``, each run with
its own code on ``PYTHONPATH`` and this checkout's interpreter), import the planner as the
bench's workers do (:mod:`ldhp_tamp.solver_preload`) and load the scenario once. For each
seed the coordinator asks both for a solve, A then B for one seed and B then A for the
next, and each worker solves in a child it forks for that solve (as a bench cell runs), so
that both trees see the same machine at nearly the same moment. Reported: each tree's
median solver time (``stats.time_s``: total and per tier), and the paired differences
B - A: their median and mean, and in how many pairs B was faster; and whether the two
made plans of the same number of steps.

Why not two ``ldhp-tamp bench`` runs, interleaved? This machine's speed drifts between
runs by 10-25 %, and a run of 15 seeds is long enough to drift within. Measured on
2026-12-07 (twelfth session), the same code in two checkouts, task 1 at 70 degrees:
benches of 15 seeds interleaved by run (4 runs each) gave a paired median difference of
+0.048 s, while this script (3 x 15 pairs) gave -0.009 s. A change of a few hundredths of
a second is read here, not there (``docs/benchmarks.md``, "Issue 17: one fork fewer").

Each tree needs its compiled modules (``geometry/_kernels``, ``ldhp_tamp/_search``):
``pip install -e`` builds them in place, or copy them from a checkout whose C sources are
the same; without them a tree runs with numpy alone, which is slower. Run::

    .venv/bin/python benchmarks/paired.py --a /tmp/before --b . \\
        scenarios/task1_zero_mobility_lift_tilt70.toml [--seeds 15] [--reps 3] [--prior FILE]

An older commit's tree: ``git worktree add /tmp/before REV``. Exit status 0 whatever the
figures (2 when a worker fails: its error is printed).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import statistics
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import IO

TIERS = ("setup", "symbolic", "streams", "grasp_graph")

# One worker: reads seeds on stdin, writes one JSON line per solve on stdout.
WORKER = r"""
import json, os, sys
import ldhp_tamp.solver_preload  # noqa: F401  (the planner and the engines, as the bench's workers)
from ldhp_tamp.prior import read_prior
from ldhp_tamp.scenario import load_scenario
from ldhp_tamp.tamp import SolveOptions, solve

prior = read_prior(sys.argv[2]) if sys.argv[2] else None
scenario = load_scenario(sys.argv[1])
for line in sys.stdin:
    seed = int(line)
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(read_end)
        res = solve(scenario, SolveOptions(seed=seed, prior=prior))
        out = dict(res.plan.stats.time_s, steps=len(res.plan.steps), status=res.plan.status.value)
        os.write(write_end, json.dumps(out).encode())
        os._exit(0)
    os.close(write_end)
    chunks = []
    while chunk := os.read(read_end, 1 << 16):
        chunks.append(chunk)
    os.close(read_end)
    os.waitpid(pid, 0)
    sys.stdout.write(b"".join(chunks).decode() + "\n")
    sys.stdout.flush()
"""


@dataclass
class _Worker:
    """A worker process on one tree's code; its messages go to a file (a pipe nobody reads
    while it solves could fill up and stop it), read back when it fails."""

    name: str
    proc: subprocess.Popen[str]
    log: IO[str]

    @classmethod
    def start(cls, name: str, tree: Path, scenario: Path, prior: Path | None) -> "_Worker":
        log = tempfile.TemporaryFile(mode="w+")
        proc = subprocess.Popen([sys.executable, "-c", WORKER, str(scenario), str(prior or "")], cwd=tree,
                                env=dict(os.environ, PYTHONPATH=str(tree)), stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=log, text=True)
        return cls(name, proc, log)

    def solve(self, seed: int) -> dict[str, object]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        try:
            self.proc.stdin.write(f"{seed}\n")
            self.proc.stdin.flush()
            line = self.proc.stdout.readline()
        except BrokenPipeError:
            line = ""
        if not line.strip():
            self.proc.kill()
            self.proc.wait()
            self.log.seek(0)
            raise RuntimeError(f"the worker of {self.name} failed at seed {seed}:\n{self.log.read().strip()}")
        return json.loads(line)

    def stop(self) -> None:
        if self.proc.stdin is not None:
            with contextlib.suppress(BrokenPipeError):
                self.proc.stdin.close()
        self.proc.wait()
        self.log.close()


def paired(a: Path, b: Path, scenario: Path, seeds: int, reps: int, prior: Path | None = None
           ) -> dict[str, list[dict[str, object]]]:
    """The solves of both trees, in pairs: ``{"a": [...], "b": [...]}``, the same seed at
    the same index (``reps`` rounds of seeds 0 .. seeds - 1)."""
    workers = {"a": _Worker.start("a", a, scenario, prior), "b": _Worker.start("b", b, scenario, prior)}
    out: dict[str, list[dict[str, object]]] = {"a": [], "b": []}
    try:
        i = 0
        for _ in range(reps):
            for seed in range(seeds):
                for name in ("a", "b") if i % 2 == 0 else ("b", "a"):
                    out[name].append(workers[name].solve(seed))
                i += 1
    finally:
        for w in workers.values():
            w.stop()
    return out


def report(res: dict[str, list[dict[str, object]]]) -> str:
    """The medians per tree and the paired differences, as text."""
    def med(rows: list[dict[str, object]], key: str) -> float:
        return statistics.median(float(r[key]) for r in rows)  # type: ignore[arg-type]

    lines = []
    for name in ("a", "b"):
        rows = res[name]
        solved = sum(r["status"] == "solved" for r in rows)
        lines.append(f"{name}: {solved}/{len(rows)} solved, median total {med(rows, 'total'):.3f} s ("
                     + ", ".join(f"{t} {med(rows, t):.3f}" for t in TIERS) + ")")
    pairs = list(zip(res["a"], res["b"]))
    d = [float(y["total"]) - float(x["total"]) for x, y in pairs]  # type: ignore[arg-type]
    lines.append(f"paired b - a: median {statistics.median(d):+.3f} s, mean {statistics.mean(d):+.3f} s, "
                 f"b faster in {sum(x < 0 for x in d)} of {len(d)}")
    for t in TIERS:
        dt = [float(y[t]) - float(x[t]) for x, y in pairs]  # type: ignore[arg-type]
        lines.append(f"  {t}: median {statistics.median(dt):+.3f} s")
    same = all(x["steps"] == y["steps"] and x["status"] == y["status"] for x, y in pairs)
    lines.append("the same outcome and number of steps in every pair" if same else
                 "OUTCOMES DIFFER: the trees made different plans")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenario", type=Path)
    ap.add_argument("--a", type=Path, required=True, help="the tree before (its code is run)")
    ap.add_argument("--b", type=Path, required=True, help="the tree after")
    ap.add_argument("--seeds", type=int, default=15)
    ap.add_argument("--reps", type=int, default=3, help="rounds over the seeds (default 3)")
    ap.add_argument("--prior", type=Path, default=None, help="a transition prior for both (ldhp-tamp prior)")
    args = ap.parse_args(argv)
    for flag, tree in (("--a", args.a), ("--b", args.b)):
        if not (tree / "ldhp_tamp" / "tamp.py").is_file():
            print(f"paired.py: {flag} {tree}: not a checkout of ldhp-tamp (no ldhp_tamp/tamp.py there)",
                  file=sys.stderr)
            return 2
    if not args.scenario.is_file():
        print(f"paired.py: {args.scenario}: no such scenario file", file=sys.stderr)
        return 2
    try:
        res = paired(args.a.resolve(), args.b.resolve(), args.scenario.resolve(), args.seeds, args.reps,
                     args.prior.resolve() if args.prior else None)
    except RuntimeError as exc:
        print(f"paired.py: {exc}", file=sys.stderr)
        return 2
    print(report(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
