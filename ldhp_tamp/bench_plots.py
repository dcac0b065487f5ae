"""Figures from benchmark rows (:mod:`ldhp_tamp.bench`), PNG and SVG: the planners
compared per scenario (:func:`plot_comparison`: success rate with its 95 % Wilson interval,
solve time median and quartiles), and planning time against K (samples per edge) and
against the object's vertex count (:func:`plot_scaling`).

matplotlib is imported when a figure is drawn, with the ``Agg`` backend (no display).
Each figure has two panels: the solve time (``time_total_s``) and the number of
feasibility checks, each on a log scale when its values span more than a factor 10. A
line joins the medians over seeds of solved runs, dots are single solved runs, crosses
runs that were not solved (failed at the time shown, or stopped by the time limit, drawn
at the limit). The x axis is logarithmic for K, linear for the vertex count.
"""

from __future__ import annotations

import logging
import math
import os
import statistics
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any
from pathlib import Path

from ldhp_tamp.bench import BenchRow, BenchStatus
from ldhp_tamp.files import atomic_output

__all__ = ["Axis", "COMPARISON", "SAMPLES", "VERTICES", "plot_comparison", "plot_scaling", "write_plots"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Axis:
    """What goes on the x axis: a :class:`BenchRow` field, its label, the fields that
    name a series (one line each), and the figure's file stem."""

    field: str
    label: str
    series: tuple[str, ...]
    stem: str
    title: str
    log_x: bool = True


SAMPLES = Axis("samples_per_edge", "K, grasp samples per object edge", ("scenario", "engine"),
               "time_vs_samples", "Cost against the grasp sampling density K")
VERTICES = Axis("object_vertices", "object vertices (regular polygon)", ("engine", "samples_per_edge"),
                "time_vs_vertices", "Cost against the object's complexity", log_x=False)

_PANELS = (("time_total_s", "planning time (s)"), ("feasibility_checks", "feasibility checks"))
#: A panel's y axis is logarithmic when its values span more than this factor.
_LOG_SPAN = 10.0


def _label(row: BenchRow, fields: Sequence[str]) -> str:
    parts = []
    for f in fields:
        v = getattr(row, f)
        parts.append(f"K={v}" if f == "samples_per_edge" else str(v))
    return ", ".join(parts)


def _short(y: float) -> str:
    """Tick label: 0.3, 2, 60k, 1.2M (no powers of ten)."""
    if y >= 1e6:
        return f"{y / 1e6:g}M"
    if y >= 1e3:
        return f"{y / 1e3:g}k"
    return f"{y:g}"


def _minor_label(y: float, _pos: int) -> str:
    """Label the minor ticks 2x and 5x a power of ten, so a log axis reads without
    powers of ten and without crowding."""
    mantissa = y / 10 ** math.floor(math.log10(y) + 1e-9)
    return _short(y) if round(mantissa) in (2, 5) and abs(mantissa - round(mantissa)) < 1e-6 else ""


def plot_scaling(rows: Sequence[BenchRow], axis: Axis, out_dir: str | os.PathLike[str],
                 hard_limit_s: float | None = None) -> tuple[Path, Path] | None:
    """Draw ``rows`` against ``axis``; write ``<stem>.png`` and ``<stem>.svg`` atomically.

    Returns the two paths, or ``None`` (and draws nothing) when the rows hold fewer than
    two distinct x values.
    """
    xs = {getattr(r, axis.field) for r in rows}
    if len(xs) < 2:
        log.info("%s: fewer than two values of %s; no figure", axis.stem, axis.field)
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, NullFormatter

    series: dict[str, list[BenchRow]] = {}
    for r in rows:
        series.setdefault(_label(r, axis.series), []).append(r)
    fig, panels = plt.subplots(1, len(_PANELS), figsize=(11, 4.4), constrained_layout=True)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    markers = "osD^vP*X"
    drawn: dict[str, list[float]] = {metric: [] for metric, _ in _PANELS}
    for i, (name, rs) in enumerate(sorted(series.items())):
        colour, marker = colours[i % len(colours)], markers[i % len(markers)]
        for ax, (metric, _ylabel) in zip(panels, _PANELS):
            solved = [r for r in rs if r.status is BenchStatus.SOLVED and getattr(r, metric) is not None]
            by_x: dict[int, list[float]] = {}
            for r in solved:
                by_x.setdefault(getattr(r, axis.field), []).append(getattr(r, metric))
            mx = sorted(by_x)
            ax.plot(mx, [statistics.median(by_x[x]) for x in mx], color=colour, marker=marker,
                    label=name, linewidth=1.6, markersize=6)
            ax.scatter([getattr(r, axis.field) for r in solved], [getattr(r, metric) for r in solved],
                       color=colour, s=10, alpha=0.45, zorder=3)
            bad = []
            for r in rs:
                if r.status is BenchStatus.SOLVED:
                    continue
                y = getattr(r, metric)
                if y is None and metric == "time_total_s" and r.status is BenchStatus.TIMEOUT:
                    y = hard_limit_s or r.wall_s
                if y:
                    bad.append((getattr(r, axis.field), y))
            if bad:
                ax.scatter(*zip(*bad), color=colour, marker="x", s=45, zorder=4)
            drawn[metric] += [getattr(r, metric) for r in solved] + [y for _x, y in bad]
    plain = FuncFormatter(lambda y, _pos: _short(y))
    for ax, (metric, ylabel) in zip(panels, _PANELS):
        if axis.log_x:
            ax.set_xscale("log")
        ticks = sorted(xs)
        ax.set_xticks(ticks, [str(t) for t in ticks])
        ax.xaxis.set_minor_formatter(NullFormatter())  # the runs' x values only
        ys = [y for y in drawn[metric] if y > 0]
        if ys and max(ys) > _LOG_SPAN * min(ys):
            ax.set_yscale("log")
            ylabel += ", log scale"
            ax.yaxis.set_minor_formatter(FuncFormatter(_minor_label))
            ax.tick_params(axis="y", which="minor", labelsize=7)
            ax.grid(True, which="minor", axis="y", alpha=0.12)
        else:
            ax.set_ylim(bottom=0)
        ax.yaxis.set_major_formatter(plain)
        ax.set_xlabel(axis.label)
        ax.set_ylabel(ylabel)
        ax.grid(True, which="major", alpha=0.35)
    handles, labels = panels[0].get_legend_handles_labels()
    if any(r.status is not BenchStatus.SOLVED for r in rows):
        handles.append(plt.Line2D([], [], color="grey", marker="x", linestyle="none"))
        labels.append("not solved")
    handles.append(plt.Line2D([], [], color="grey", marker="o", markersize=3, alpha=0.5, linestyle="none"))
    labels.append("one solved run (line: median)")
    panels[0].legend(handles, labels, fontsize=8, loc="best")
    fig.suptitle(axis.title)
    return _save(fig, out_dir, axis.stem)


COMPARISON = "comparison"


def plot_comparison(rows: Sequence[BenchRow], out_dir: str | os.PathLike[str],
                    stem: str = COMPARISON) -> tuple[Path, Path] | None:
    """Planners side by side, one group of bars per scenario, one bar per planner (and
    engine, when the rows hold several): the success rate over the seeds with its 95 %
    Wilson interval, and the solve time of the solved runs (median, the bar from the
    first to the third quartile; log scale when the times span more than a factor 10).
    Writes ``<stem>.png`` and ``<stem>.svg``; ``None`` when there are no rows."""
    if not rows:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    from ldhp_tamp.bench import quartiles, wilson_interval

    scenarios = sorted({r.scenario for r in rows})
    engines = {r.engine for r in rows if r.engine}

    def series_of(r: BenchRow) -> str:
        return f"{r.planner} ({r.engine})" if len(engines) > 1 and r.engine else r.planner

    series = list(dict.fromkeys(series_of(r) for r in rows))
    width = 0.8 / len(series)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    fig, (ax_s, ax_t) = plt.subplots(2, 1, figsize=(min(16.0, max(7.0, 0.8 * len(scenarios) + 3)), 7.5),
                                     constrained_layout=True, sharex=True)
    times: list[float] = []
    for j, name in enumerate(series):
        colour = colours[j % len(colours)]
        xs, rate, err_lo, err_hi = [], [], [], []
        tx, tmed, tlo, thi = [], [], [], []
        for i, sc in enumerate(scenarios):
            rs = [r for r in rows if r.scenario == sc and series_of(r) == name]
            if not rs:
                continue
            x = i - 0.4 + width * (j + 0.5)
            ok = [r for r in rs if r.status is BenchStatus.SOLVED]
            lo, hi = wilson_interval(len(ok), len(rs))
            p = len(ok) / len(rs)
            xs.append(x)
            rate.append(100 * p)
            err_lo.append(100 * max(0.0, p - lo))  # 2 of 2: hi rounds to 1 - 1e-16
            err_hi.append(100 * max(0.0, hi - p))
            q = quartiles([r.time_total_s for r in ok if r.time_total_s is not None])
            if q is not None:
                tx.append(x)
                tmed.append(q[1])
                tlo.append(q[1] - q[0])
                thi.append(q[2] - q[1])
                times += [q[0], q[2]]
        ax_s.bar(xs, rate, width * 0.9, yerr=[err_lo, err_hi], color=colour, label=name, capsize=3,
                 error_kw={"elinewidth": 1, "ecolor": "black", "alpha": 0.7})
        if tx:
            ax_t.errorbar(tx, tmed, yerr=[tlo, thi], fmt="o", color=colour, capsize=3, markersize=5)
    ax_s.set_ylim(0, 105)
    ax_s.set_ylabel("solved (%), 95 % Wilson interval")
    ax_s.legend(fontsize=8, loc="best")
    ax_s.grid(True, axis="y", alpha=0.35)
    positive = [t for t in times if t > 0]
    if positive and max(positive) > _LOG_SPAN * min(positive):
        ax_t.set_yscale("log")
        ax_t.set_ylabel("solve time, solved runs (s, log scale)\nmedian and quartiles")
        ax_t.yaxis.set_major_formatter(FuncFormatter(lambda y, _pos: _short(y)))
    else:
        ax_t.set_ylim(0, 1.1 * max(positive) if positive else 1.0)
        ax_t.set_ylabel("solve time, solved runs (s)\nmedian and quartiles")
    ax_t.grid(True, axis="y", alpha=0.35)
    ax_t.set_xticks(range(len(scenarios)), scenarios, rotation=30, ha="right", fontsize=8)
    seeds = len({r.seed for r in rows})
    fig.suptitle(f"Planners compared ({seeds} seed{'s' if seeds != 1 else ''} per scenario)")
    return _save(fig, out_dir, stem)


def _save(fig: Any, out_dir: str | os.PathLike[str], stem: str) -> tuple[Path, Path]:
    """Write ``fig`` as ``stem.png`` and ``stem.svg`` in ``out_dir`` (each file whole or
    not at all) and close it."""
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    paths = (out / f"{stem}.png", out / f"{stem}.svg")
    for path in paths:
        with atomic_output(path, binary=True) as (f, _tmp):
            fig.savefig(f, format=path.suffix[1:], dpi=150)
    plt.close(fig)
    return paths


def write_plots(rows: Sequence[BenchRow], out_dir: str | os.PathLike[str],
                hard_limit_s: float | None = None) -> list[Path]:
    """Every figure the rows support: the planners compared (success rate and time per
    scenario), against K when they hold two or more K values, against the vertex count
    when two or more vertex counts. Returns the files written."""
    written: list[Path] = list(plot_comparison(rows, out_dir) or ())
    for axis in (SAMPLES, VERTICES):
        paths = plot_scaling(rows, axis, out_dir, hard_limit_s)
        if paths:
            written.extend(paths)
    return written
