"""How the planning cost grows: two sweeps through the benchmark harness, with figures.

1. **K** (grasp samples per object edge, the paper's K): the spec's pick example and the
   paper's task 1 at K = 10, 25, 50, 100, 200.
2. **Object complexity**: regular polygons of 4..12 vertices (circumradius 40 mm, resting
   on an edge), picked up 100 mm by the gripper of ``scenarios/example_pick.toml`` from
   the same table: the pick example with only the object changed. The generated
   scenarios are written next to the results (``vertices/scenarios/``), so any run can be
   repeated with ``ldhp-tamp solve``.

Each sweep is one :func:`ldhp_tamp.bench.run_bench` (worker processes, CSV, JSON,
Markdown summary) followed by :func:`ldhp_tamp.bench_plots.write_plots` and
:func:`growth`, how the solve time grows with the grasp graph's size (``growth.md``)::

    OUT/samples/   runs.csv runs.json summary.md growth.md time_vs_samples.png time_vs_samples.svg
    OUT/vertices/  scenarios/polygon-NN.toml runs.csv ... growth.md time_vs_vertices.png .svg

Run::

    .venv/bin/python benchmarks/scaling.py --out bench-scaling --seeds 2 --jobs 2
    .venv/bin/python benchmarks/scaling.py --engines pyperplan,fast-downward --only vertices
    .venv/bin/python benchmarks/scaling.py --task1 scenarios/task1_zero_mobility_lift_tilt70.toml --only samples

Exit status 0 when the sweeps ran (whatever the solves' outcomes), 2 on bad input.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ldhp_tamp.bench import BenchOptions, run_bench
from ldhp_tamp.bench_plots import write_plots
from ldhp_tamp.errors import InputError
from ldhp_tamp.files import write_text_atomic
from ldhp_tamp.resources import scenarios_dir

PICK = scenarios_dir() / "example_pick.toml"
TASK1 = scenarios_dir() / "task1_zero_mobility_lift.toml"
SAMPLES = (10, 25, 50, 100, 200)
VERTICES = tuple(range(4, 13))


def regular_polygon(n: int, radius: float = 40.0) -> list[list[float]]:
    """The ``n`` vertices (counter-clockwise, mm) of a regular polygon of circumradius
    ``radius`` with a horizontal bottom edge, shifted so that ``min x = min y = 0``."""
    if n < 3:
        raise ValueError(f"a polygon needs 3 or more vertices, got {n}")
    angles = [-math.pi / 2 - math.pi / n + 2 * math.pi * k / n for k in range(n)]
    pts = [(radius * math.cos(a), radius * math.sin(a)) for a in angles]
    x0, y0 = min(p[0] for p in pts), min(p[1] for p in pts)
    return [[round(x - x0, 4), round(y - y0, 4)] for x, y in pts]


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # a TOML basic string for the texts used here
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} as a TOML value")


def _toml(table: Mapping[str, Any], prefix: str = "") -> list[str]:
    """TOML text of a parsed document: scalars, then tables, then arrays of tables."""
    lines = [f"{k} = {_toml_value(v)}" for k, v in table.items()
             if not isinstance(v, dict) and not (isinstance(v, list) and v and isinstance(v[0], dict))]
    for k, v in table.items():
        name = f"{prefix}{k}"
        if isinstance(v, dict):
            body = _toml(v, name + ".")
            if not body or body[0] != "":  # a table with keys of its own (no bare [environment])
                lines += ["", f"[{name}]"]
            lines += body
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for item in v:
                lines += ["", f"[[{name}]]", *_toml(item, name + ".")]
    return lines


def polygon_scenario(n: int, template: Path = PICK, radius: float = 40.0) -> str:
    """The ``template`` scenario (the pick example) with its object replaced by a regular
    ``n``-gon: same table, gripper, friction and task. Returns TOML text."""
    doc = tomllib.loads(template.read_text(encoding="utf-8"))
    doc["name"] = f"polygon-{n:02d}"
    doc["description"] = (f"{template.name} with a regular {n}-gon (circumradius {radius:g} mm) "
                          "instead of its block: object complexity sweep")
    doc["object"] = {"vertices": regular_polygon(n, radius)}
    return "\n".join(_toml(doc)) + "\n"


def _parse(argv: Sequence[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", default="bench-scaling", help="output directory (default: bench-scaling)")
    p.add_argument("--engines", default="pyperplan", help="comma-separated engines (default: pyperplan)")
    p.add_argument("--seeds", type=int, default=2, help="seeds per point (default 2)")
    p.add_argument("--jobs", type=int, default=1, help="worker processes at once (default 1)")
    p.add_argument("--timeout", type=float, default=120.0, help="seconds per run (default 120)")
    p.add_argument("--samples", default=",".join(map(str, SAMPLES)), help="K values of the K sweep")
    p.add_argument("--vertices", default=",".join(map(str, VERTICES)), help="vertex counts of the polygon sweep")
    p.add_argument("--only", choices=("samples", "vertices"), help="run one sweep only")
    p.add_argument("--task1", default=str(TASK1), help="the task 1 scenario of the K sweep (default: as shipped)")
    return p.parse_args(argv)


def _slope(xs: Sequence[float], ys: Sequence[float]) -> float:
    """Least-squares slope of log y against log x (nan with fewer than two sizes)."""
    lx, ly = [math.log(x) for x in xs], [math.log(y) for y in ys]
    mx, my = sum(lx) / len(lx), sum(ly) / len(ly)
    den = sum((x - mx) ** 2 for x in lx)
    return math.nan if den == 0 else sum((x - mx) * (y - my) for x, y in zip(lx, ly)) / den


def growth(rows: Sequence[Any]) -> str:
    """How the solve time grows with the grasp graph: per scenario, the solved runs'
    ``time_total_s`` and ``time_grasp_graph_s`` against ``grasp_graph_edges`` (and
    nodes), and the exponent b of ``time ~ size^b`` fitted on a log-log scale (b <= 1:
    no faster than linearly). A Markdown table and one line per scenario."""
    lines = ["| scenario | K | vertices | seed | nodes | edges | feasibility checks | time (s) | grasp-graph tier (s) |",
             "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |"]
    fits = []
    by: dict[str, list[Any]] = {}
    for r in rows:
        if r.status.value == "solved" and r.grasp_graph_edges and r.time_total_s:
            by.setdefault(r.scenario if not r.scenario.startswith("polygon") else "polygons", []).append(r)
    for name, rs in by.items():
        rs.sort(key=lambda r: (r.grasp_graph_edges, r.seed))
        for r in rs:
            lines.append(f"| {r.scenario} | {r.samples_per_edge} | {r.object_vertices} | {r.seed} | "
                         f"{r.grasp_graph_nodes} | {r.grasp_graph_edges} | {r.feasibility_checks} | "
                         f"{r.time_total_s:.2f} | {r.time_grasp_graph_s:.2f} |")
        edges = [float(r.grasp_graph_edges) for r in rs]
        b_total = _slope(edges, [r.time_total_s for r in rs])
        b_gg = _slope(edges, [max(r.time_grasp_graph_s, 1e-3) for r in rs])
        b_nodes = _slope([float(r.grasp_graph_nodes) for r in rs], [r.time_total_s for r in rs])
        fits.append(f"- {name}: {len(rs)} solved runs, edges {int(min(edges))}-{int(max(edges))}; "
                    f"time ~ edges^{b_total:.2f} (grasp-graph tier ~ edges^{b_gg:.2f}), time ~ nodes^{b_nodes:.2f}")
    return "\n".join(lines + [""] + fits) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    args = _parse(argv)

    def say(msg: str) -> None:
        print(f"[scaling] {msg}", file=sys.stderr, flush=True)

    out = Path(args.out)
    engines = tuple(e.strip() for e in args.engines.split(",") if e.strip())
    try:
        ks = tuple(int(k) for k in args.samples.split(","))
        ns = tuple(int(n) for n in args.vertices.split(","))
        if args.only != "vertices":
            options = BenchOptions(engines=engines, seeds=args.seeds, samples=ks,
                                   timeout_s=args.timeout, jobs=args.jobs)
            rows, files = run_bench([PICK, Path(args.task1)], options, out / "samples", progress=say)
            figures = write_plots(rows, out / "samples", options.hard_limit_s)
            write_text_atomic(out / "samples" / "growth.md", growth(rows))
            say(f"K sweep: {files.summary}, " + ", ".join(map(str, figures)))
        if args.only != "samples":
            folder = out / "vertices" / "scenarios"
            folder.mkdir(parents=True, exist_ok=True)
            paths = [write_text_atomic(folder / f"polygon-{n:02d}.toml", polygon_scenario(n)) for n in ns]
            options = BenchOptions(engines=engines, seeds=args.seeds, timeout_s=args.timeout, jobs=args.jobs)
            rows, files = run_bench(paths, options, out / "vertices", progress=say)
            figures = write_plots(rows, out / "vertices", options.hard_limit_s)
            write_text_atomic(out / "vertices" / "growth.md", growth(rows))
            say(f"vertex sweep: {files.summary}, " + ", ".join(map(str, figures)))
    except (InputError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
