"""Replay every plan of ``docs/results/plans/`` in MuJoCo (``ldhp-tamp simulate``) and print
a table: plan, steps, waypoints, simulated seconds, wall seconds, verdict, diverging step.

Each plan is matched to its scenario in ``scenarios/`` by the plan file's stem
(``<stem>-plan.json`` -> ``scenarios/<stem>.toml``), else by the scenario name the plan
names. Plans that are failed solves are listed as ``not simulated``.

Run::

    .venv/bin/python benchmarks/simulate_bench.py
    .venv/bin/python benchmarks/simulate_bench.py --plans docs/results/plans --speed 10 --out bench-sim/
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from ldhp_tamp.plan import read_plan  # noqa: E402
from ldhp_tamp.scenario import load_scenario  # noqa: E402
from ldhp_tamp.simulate import SimOptions, SimStatus, simulate_plan, write_report  # noqa: E402


def _scenario_for(plan_path: Path, scenario_name: str, scenarios: Path) -> Path | None:
    stem = plan_path.name.removesuffix(".json").removesuffix("-plan")
    direct = scenarios / f"{stem}.toml"
    if direct.is_file():
        return direct
    for candidate in sorted(scenarios.glob("*.toml")):
        try:
            if load_scenario(candidate, check_planner=False).name == scenario_name:
                return candidate
        except Exception:  # noqa: BLE001 - a broken scenario is simply not a match
            continue
    return None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--plans", default=str(ROOT / "docs" / "results" / "plans"), help="folder of plan JSON files")
    ap.add_argument("--scenarios", default=str(ROOT / "scenarios"), help="folder of scenario TOML files")
    ap.add_argument("--speed", type=float, default=SimOptions().speed_mm_s, help="hand speed (mm/s)")
    ap.add_argument("--out", help="also write one simulation report per plan into this folder")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    options = SimOptions(speed_mm_s=args.speed)
    out = Path(args.out) if args.out else None
    if out:
        out.mkdir(parents=True, exist_ok=True)
    rows = []
    for plan_path in sorted(Path(args.plans).glob("*.json")):
        plan = read_plan(plan_path)
        scen_path = _scenario_for(plan_path, plan.scenario, Path(args.scenarios))
        name = plan_path.name.removesuffix(".json")
        if scen_path is None:
            rows.append((name, "-", "-", "-", "-", "no scenario", "-", ""))
            continue
        scenario = load_scenario(scen_path, check_planner=False)
        report = simulate_plan(plan, scenario, options)
        if out:
            write_report(report, out / f"{name}-sim.json", str(plan_path), str(scen_path), options)
        if report.status is SimStatus.DIVERGES:
            where = f"{report.diverged_step} ({report.diverged_primitive})"
        else:
            where = "-"
        rows.append((name, str(len(plan.steps)), str(len(plan.waypoints)), f"{report.simulated_s:.1f}",
                     f"{report.wall_s:.1f}", report.status.value, where,
                     "a failed plan (no steps)" if report.status is SimStatus.NOT_SIMULATED else report.reason))
        print(f"[simulate_bench] {name}: {report.status.value} {where} ({report.wall_s:.1f} s)",
              file=sys.stderr, flush=True)
    head = ("plan", "steps", "waypoints", "simulated s", "wall s", "verdict", "diverging step", "reason")
    print("| " + " | ".join(head) + " |")
    print("| " + " | ".join("---" for _ in head) + " |")
    for row in rows:
        print("| " + " | ".join(row) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
