"""Regenerate ``docs/results.md``: the scenario suite, the paper's Table III, figures.

Run from the repository root::

    .venv/bin/python benchmarks/results.py [--timeout S] [--jobs J] [--out docs/results.md]
                                           [--only NAME,...] [--skip-ablation] [--skip-figures]

Everything is done with the project's own machinery:

1. **Scenario suite**: every ``scenarios/*.toml`` (or the ``--only`` stems) is one run of
   the benchmark harness (:func:`ldhp_tamp.bench.plan_runs` and
   :func:`ldhp_tamp.bench.run_all`: a worker process per run, the scenario's own engine
   and K, seed 0, with the simulation judge (``solve --simulate``: a plan that diverges in
   the physics replay is fed back and the search goes on), ``BenchOptions(timeout_s=S,
   jobs=J, judge_simulate=True)``). Each worker writes its plan
   (solved or failed) to ``RESULTS/plans/<stem>-plan.json`` (``RunSpec.plan_file``); every
   solved plan is read back and checked again with
   :func:`ldhp_tamp.validate.validate_plan`.
2. **Ablation** (the paper's Table III): :func:`ldhp_tamp.ablate.ablate` on task 1 and
   task 2, compared cell by cell with the paper's values (:data:`PAPER_TABLE3`);
   ``RESULTS/ablation.csv`` by :func:`ldhp_tamp.ablate.write_csv`.
3. **Figures**: the snapshots and the contact-state graph of the solved plans of task 1
   and task 2, by :func:`ldhp_tamp.render.render_files`, PNG only, into
   ``RESULTS/figures/<stem>/``.

``RESULTS`` is the folder named after the output file, next to it: ``docs/results/`` for
``docs/results.md``.

The document mixes generated text and the maintainers' commentary. Only what lies between
``<!-- BEGIN generated: NAME -->`` and ``<!-- END generated: NAME -->`` is replaced (NAME
in :data:`BLOCKS`); the rest is kept byte for byte. Every block must be there once (a
missing marker exits 2 before anything runs); a missing document is created from
:func:`skeleton`. A block that this run does not produce (``--skip-ablation``,
``--skip-figures``, figures when ``--only`` leaves out both tasks) keeps its old text; each
block starts with a line saying when and at which commit it was generated.

``--only`` limits what is run *and* written: the suite table then lists only those
scenarios (the rows of the others are dropped, not kept). It is for quick checks.

Exit status: 0 when it ran, whatever the solves' outcomes; 2 on bad input (an unknown
``--only`` stem, a non-positive ``--timeout`` or ``--jobs``, a missing marker, an output
that cannot be written), with a one-line message.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import platform
import shlex
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from datetime import datetime, timezone
from itertools import groupby
from pathlib import Path

from ldhp_tamp.ablate import BASELINE, AblationOptions, AblationTable, ablate, write_csv
from ldhp_tamp.bench import BenchOptions, BenchRow, BenchStatus, plan_runs, run_all
from ldhp_tamp.errors import InputError
from ldhp_tamp.files import write_bytes_atomic, write_text_atomic
from ldhp_tamp.plan import read_plan
from ldhp_tamp.render import RenderOptions, render_files
from ldhp_tamp.scenario import load_scenario
from ldhp_tamp.validate import format_violation, validate_plan

log = logging.getLogger("results")

REPO = Path(__file__).resolve().parents[1]
SCENARIOS = REPO / "scenarios"
DEFAULT_OUT = Path("docs/results.md")
DEFAULT_TIMEOUT_S = 120.0
SCRIPT = "benchmarks/results.py"

#: The generated blocks, in the order of the skeleton.
BLOCKS: tuple[str, ...] = ("context", "suite", "suite-details", "ablation", "figures")

#: Task 1 as the paper leaves it open (the final tilt): held at 70 degrees, the variant
#: with a hold that executes (at 60 degrees the hold is at the edge of its friction cone).
TASK1 = "task1_zero_mobility_lift_tilt70"
TASK2 = "task2_slot_insertion"
#: The scenarios of the ablation (the columns of Table III) and of the figures.
ABLATION_STEMS: tuple[str, str] = (TASK1, TASK2)
FIGURE_STEMS: tuple[str, ...] = (TASK1, TASK2)

#: The paper's Table III: removed primitive -> (task 1 feasible, task 2 feasible). The
#: baseline (nothing removed) is not a row of the paper's table; the paper solves both
#: tasks with the full library, so it is Y, Y here.
PAPER_TABLE3: Mapping[str, tuple[bool, bool]] = {
    BASELINE: (True, True),
    "tip": (False, True),
    "push": (False, False),
    "biplanar-slide": (False, False),
    "air-move": (False, False),
    "approach-contact": (False, False),
    "open": (False, False),
    "close": (False, True),
    "pivot": (False, False),
    "slide": (True, True),
    "flip": (False, False),
}

#: The figures kept from a render (the SVGs and the GIF are dropped).
FIGURE_PNGS: tuple[str, ...] = ("snapshots.png", "contact_graph.png")
#: Resolutions tried in turn until every PNG is below :data:`PNG_LIMIT_BYTES`.
FIGURE_DPIS: tuple[int, ...] = (110, 80, 60)
PNG_LIMIT_BYTES = 400_000

#: Length of a reason in a table cell; the full reason is in the details list.
REASON_CELL_CHARS = 150
#: Violations listed in full for a plan that does not validate.
MAX_VIOLATIONS = 10

_DISAGREE = "≠"


class MarkerError(InputError):
    """A document whose generated blocks cannot be found: the message names the marker."""


# --------------------------------------------------------------------------- values


@dataclass(frozen=True)
class OutputPaths:
    """Where everything is written: the document and the folder beside it."""

    document: Path
    results: Path
    plans: Path
    figures: Path
    ablation_csv: Path

    @classmethod
    def of(cls, document: Path) -> "OutputPaths":
        """The paths for ``document``: ``<parent>/<stem>/plans``, ``.../figures``, ...

        >>> OutputPaths.of(Path("docs/results.md")).plans.as_posix()
        'docs/results/plans'
        """
        results = document.with_suffix("")
        return cls(document, results, results / "plans", results / "figures", results / "ablation.csv")

    def plan(self, stem: str) -> Path:
        return self.plans / f"{stem}-plan.json"


@dataclass(frozen=True)
class RunContext:
    """What a reader needs to reproduce the numbers."""

    date: str
    commit: str
    dirty: tuple[str, ...] | None  # paths differing from the commit; None: unknown
    cpus: int | None
    python: str
    platform: str
    timeout_s: float
    grace_s: float
    jobs: int
    command: str

    @property
    def stamp(self) -> str:
        """The provenance line at the head of every generated block."""
        tree = " (dirty tree)" if self.dirty else ""
        return f"_Generated by `{SCRIPT}` on {self.date} at commit `{self.commit}`{tree}._"


@dataclass(frozen=True)
class SuiteEntry:
    """One scenario of the suite: the harness's row, the plan file, the re-validation.

    ``validated`` is ``None`` when there is no solved plan to validate; ``problems`` says
    why it was not validated (the violations), empty otherwise.
    """

    stem: str
    row: BenchRow
    plan_file: Path | None
    primitives: tuple[str, ...]
    validated: bool | None
    problems: tuple[str, ...] = ()

    @property
    def reason(self) -> str:
        """Why this scenario is not a solved, validated plan; empty when it is."""
        if self.row.status is not BenchStatus.SOLVED:
            return " ".join(self.row.reason.split()) or "(no reason given)"
        if self.validated is False:
            return "the plan does not validate: " + "; ".join(self.problems)
        if self.row.executes is False:
            return f"the plan diverges in the physics simulation at step {self.row.diverges_at}"
        return ""


@dataclass(frozen=True)
class ComparedCell:
    """One cell of Table III: ours (``None``: not in our table) beside the paper's."""

    ours: bool | None
    paper: bool | None
    status: str = ""
    reason: str = ""
    primitives: tuple[str, ...] = ()

    @property
    def disagrees(self) -> bool:
        """Both values are known and differ."""
        return self.ours is not None and self.paper is not None and self.ours != self.paper


@dataclass(frozen=True)
class ComparedRow:
    """A row of Table III: the primitive removed, its family, a cell per task."""

    removed: str
    family: str
    cells: tuple[ComparedCell, ...]


@dataclass(frozen=True)
class FigureSet:
    """The PNGs drawn for one plan."""

    stem: str
    files: tuple[Path, ...]
    dpi: int


# --------------------------------------------------------------------------- markers


def begin_marker(name: str) -> str:
    return f"<!-- BEGIN generated: {name} -->"


def end_marker(name: str) -> str:
    return f"<!-- END generated: {name} -->"


def find_block(text: str, name: str, source: str = "<document>") -> tuple[int, int]:
    """The span of block ``name``'s content: from just after its BEGIN marker to the
    start of its END marker.

    Raises
    ------
    MarkerError
        A marker missing or repeated, or END before BEGIN (the message names the marker).
    """
    spans = []
    for marker in (begin_marker(name), end_marker(name)):
        count = text.count(marker)
        if count != 1:
            what = "is missing" if count == 0 else f"appears {count} times"
            raise MarkerError(f"{source}: the marker {marker} {what}")
        spans.append(text.index(marker))
    begin, end = spans
    if end < begin:
        raise MarkerError(f"{source}: the marker {end_marker(name)} comes before {begin_marker(name)}")
    return begin + len(begin_marker(name)), end


def check_markers(text: str, names: Sequence[str] = BLOCKS, source: str = "<document>") -> None:
    """Raise :class:`MarkerError` unless every block of ``names`` is there exactly once."""
    for name in names:
        find_block(text, name, source)


def replace_blocks(text: str, blocks: Mapping[str, str], source: str = "<document>") -> str:
    """``text`` with the content of each block of ``blocks`` replaced; every byte outside
    those blocks, the markers included, is kept.

    The new content sits on lines of its own between the markers; it takes the
    document's line ends (``\\r\\n`` if the document has any).

    >>> doc = "a\\n<!-- BEGIN generated: x -->\\nold\\n<!-- END generated: x -->\\nb\\n"
    >>> replace_blocks(doc, {"x": "new"}) == doc.replace("old", "new")
    True

    Raises
    ------
    MarkerError
        A block of ``blocks`` without both its markers (see :func:`find_block`).
    """
    newline = "\r\n" if "\r\n" in text else "\n"
    spans = sorted(((*find_block(text, name, source), name) for name in blocks), reverse=True)
    for start, end, name in spans:  # from the end: earlier offsets stay valid
        body = blocks[name].strip("\n").replace("\r\n", "\n").replace("\n", newline)
        text = text[:start] + newline + body + newline + text[end:]
    return text


def skeleton(placeholder: str = "_Not generated yet._") -> str:
    """The document when there is none yet: a title, how to regenerate it, each block
    under a heading, and a place for the maintainers' commentary after the suite and
    after the ablation."""

    def block(name: str) -> str:
        return f"{begin_marker(name)}\n{placeholder}\n{end_marker(name)}\n"

    commentary = "_Commentary: to be written by the maintainers._\n"
    return "\n".join([
        "# Results\n",
        "The planner on every shipped scenario and the paper's ablation of the primitive "
        "library (Table III), with figures of the two paper tasks. The tables and figures "
        "between the `<!-- BEGIN generated: ... -->` and `<!-- END generated: ... -->` "
        "markers are written by `benchmarks/results.py`: regenerate them from the "
        f"repository root with `.venv/bin/python {SCRIPT}` (`--help` for the options). "
        "Everything outside the markers is the maintainers' text and is kept as it is.\n",
        "## How these numbers were made\n",
        block("context"),
        "## Scenario suite\n",
        block("suite"),
        "### Scenarios not solved or not validated\n",
        block("suite-details"),
        commentary,
        "## Ablation of the primitive library (the paper's Table III)\n",
        block("ablation"),
        commentary,
        "## Figures\n",
        block("figures"),
    ])


def read_document(path: Path) -> str:
    """The document's text exactly as stored (no line-end translation), or the
    :func:`skeleton` when there is no file; its markers checked.

    Raises
    ------
    MarkerError
        A block's marker missing or repeated.
    InputError
        ``path`` cannot be read as UTF-8.
    """
    try:
        text = path.read_bytes().decode("utf-8")
    except FileNotFoundError:
        return skeleton()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read the document: {exc}") from None
    check_markers(text, BLOCKS, str(path))
    return text


# --------------------------------------------------------------------------- formatting


def compress_sequence(names: Sequence[str]) -> str:
    """Consecutive repeats as ``NAME xN``; ``-`` for no step.

    >>> compress_sequence(["tip", "slide", "slide", "slide", "push"])
    'tip, slide x3, push'
    >>> compress_sequence([])
    '-'
    """
    runs = [(name, sum(1 for _ in group)) for name, group in groupby(names)]
    return ", ".join(name if k == 1 else f"{name} x{k}" for name, k in runs) or "-"


def one_line(text: str) -> str:
    """Whitespace (newlines included) collapsed to single spaces."""
    return " ".join(text.split())


def shorten(text: str, limit: int = REASON_CELL_CHARS) -> str:
    """``text`` on one line, cut to at most ``limit`` characters with an ellipsis.

    >>> shorten("a  b\\nc", 10)
    'a b c'
    >>> shorten("abcdefghijkl", 8)
    'abcdefg…'
    """
    flat = one_line(text)
    return flat if len(flat) <= limit else flat[: limit - 1].rstrip() + "…"


def md_cell(text: str) -> str:
    """Text safe in a Markdown table cell: one line, ``|`` escaped."""
    return one_line(text).replace("|", "\\|")


def _seconds(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"


def _count(x: int | None) -> str:
    return "-" if x is None else str(x)


def _link(target: Path, document: Path) -> str:
    """``target`` relative to the document's folder, with ``/``."""
    return Path(os.path.relpath(target, document.parent)).as_posix()


def _yes_no(value: bool | None) -> str:
    return "-" if value is None else ("yes" if value else "no")


def format_context(ctx: RunContext, done: Sequence[str], skipped: Sequence[str]) -> str:
    """The ``context`` block: date, commit, machine, options, the command line."""
    if ctx.dirty is None:
        tree = "unknown (git not available)"
    elif ctx.dirty:
        shown = ", ".join(f"`{p}`" for p in ctx.dirty[:8]) + (", ..." if len(ctx.dirty) > 8 else "")
        tree = f"**dirty**: {len(ctx.dirty)} path(s) differ from the commit ({shown})"
    else:
        tree = "clean (the files this script writes aside)"
    lines = [
        ctx.stamp, "",
        f"- Date: {ctx.date}",
        f"- Commit: `{ctx.commit}`; working tree {tree}",
        f"- Machine: {ctx.cpus if ctx.cpus is not None else 'unknown'} CPUs, Python {ctx.python}, "
        f"{ctx.platform}",
        f"- Timeout: {ctx.timeout_s:g} s per solve (passed to the solver; the harness stops a suite "
        f"run after {ctx.timeout_s + ctx.grace_s:g} s); jobs: {ctx.jobs} at a time. Each scenario runs "
        f"with its own engine and K (its `[planner]` table), seed 0, and the simulation judge "
        f"(`solve --simulate`: a plan that diverges in the physics replay is fed back, the search goes on).",
        f"- Command: `{ctx.command}`",
        f"- Regenerated by this run: {', '.join(done) or 'nothing'}"
        + (f"; kept from an earlier run: {', '.join(skipped)}" if skipped else ""),
        "",
        "Times are wall-clock on a shared machine: with more jobs than free cores the runs slow "
        "each other down. Compare numbers taken with the same jobs on the same machine.",
    ]
    return "\n".join(lines)


def format_suite(entries: Sequence[SuiteEntry], document: Path, stamp: str) -> str:
    """The ``suite`` block: a count by status, then one row per scenario."""
    solved = [e for e in entries if e.row.status is BenchStatus.SOLVED]
    by_status = {s: sum(e.row.status is s for e in entries) for s in BenchStatus}
    counts = ", ".join(f"{n} {s.value}" for s, n in by_status.items() if n and s is not BenchStatus.SOLVED)
    header = ("| scenario | status | validated | executes in simulation | primitives | steps | waypoints | contact states "
              "| grasp-graph nodes | grasp-graph edges | top iterations | refinements | feasibility checks "
              "| symbolic (s) | streams (s) | grasp graph (s) | total (s) | reason |")
    lines = [
        stamp, "",
        f"{len(entries)} scenario(s): {len(solved)} solved "
        f"({sum(e.validated is True for e in solved)} validated again, "
        f"{sum(e.row.executes is True for e in solved)} executing in the physics simulation)"
        + (f", {counts}" if counts else "")
        + ". The scenario links to its plan file; times are the plan's own per tier "
        "(`stats.time_s`).", "",
        header,
        "| --- | --- | --- | --- | --- |" + " ---: |" * 12 + " --- |",
    ]
    for e in entries:
        r = e.row
        name = f"[{e.stem}]({_link(e.plan_file, document)})" if e.plan_file is not None else e.stem
        lines.append(
            f"| {name} | {r.status.value} | {_yes_no(e.validated)} | {_yes_no(r.executes)} "
            f"| {md_cell(compress_sequence(e.primitives))} "
            f"| {_count(r.steps)} | {_count(r.waypoints)} | {_count(r.contact_state_nodes)} "
            f"| {_count(r.grasp_graph_nodes)} | {_count(r.grasp_graph_edges)} | {_count(r.top_iterations)} "
            f"| {_count(r.refinements)} | {_count(r.feasibility_checks)} | {_seconds(r.time_symbolic_s)} "
            f"| {_seconds(r.time_streams_s)} | {_seconds(r.time_grasp_graph_s)} | {_seconds(r.time_total_s)} "
            f"| {md_cell(shorten(e.reason))} |")
    return "\n".join(lines)


def format_suite_details(entries: Sequence[SuiteEntry], stamp: str) -> str:
    """The ``suite-details`` block: the full reason of every scenario not solved and
    validated."""
    bad = [e for e in entries if e.reason]
    if not bad:
        return f"{stamp}\n\nEvery scenario was solved, its plan validated and executed in the physics simulation."
    lines = [stamp, ""]
    for e in bad:
        status = e.row.status.value if e.row.status is not BenchStatus.SOLVED else "solved, not validated"
        lines.append(f"- `{e.stem}` (**{status}**, {e.row.wall_s:.1f} s wall): {one_line(e.reason)}")
    return "\n".join(lines)


def compare_with_paper(table: AblationTable,
                       paper: Mapping[str, tuple[bool, ...]] = PAPER_TABLE3) -> tuple[ComparedRow, ...]:
    """Our Table III beside the paper's, a row per removed primitive (ours in our order,
    then the paper's primitives our domain does not have), a cell per task column of
    ``table`` (in order: task 1, task 2)."""
    rows: list[ComparedRow] = []
    for row in table.rows:
        theirs = paper.get(row.removed)
        cells = tuple(ComparedCell(c.feasible, theirs[i] if theirs is not None and i < len(theirs) else None,
                                   c.status, c.reason, c.primitives)
                      for i, c in enumerate(row.cells))
        family = "-" if row.family is None else row.family.value
        rows.append(ComparedRow(row.removed, family, cells))
    ours = {r.removed for r in table.rows}
    for removed, theirs in paper.items():
        if removed not in ours:
            rows.append(ComparedRow(removed, "not in our domain",
                                    tuple(ComparedCell(None, theirs[i] if i < len(theirs) else None)
                                          for i in range(len(table.scenarios)))))
    return tuple(rows)


def _yn(value: bool | None) -> str:
    return "-" if value is None else ("Y" if value else "N")


def format_compared_cell(cell: ComparedCell) -> str:
    """Our mark; a solve that did not end in a plan or a plain failure says how (``N
    (timeout)``); a disagreement with the paper is bold with ``≠``.

    >>> format_compared_cell(ComparedCell(True, False, "solved"))
    '**Y** ≠'
    >>> format_compared_cell(ComparedCell(False, False, "timeout"))
    'N (timeout)'
    """
    text = _yn(cell.ours)
    if cell.disagrees:
        text = f"**{text}** {_DISAGREE}"
    if cell.ours is not None and cell.status not in ("solved", "failed", ""):
        text += f" ({cell.status})"
    return text


def format_ablation(rows: Sequence[ComparedRow], scenarios: Sequence[str], stamp: str,
                    domain: str = "") -> str:
    """The ``ablation`` block: our Y/N beside the paper's per task, disagreements marked;
    then how many cells agree, the notes on inconclusive cells and the plans found."""
    tasks = [f"task {i + 1}" for i in range(len(scenarios))]
    header = "| primitive removed | family | " + " | ".join(f"{t}: ours | {t}: paper" for t in tasks) + " |"
    lines = [
        stamp, "",
        f"Columns: {', '.join(f'{t} = `{s}`' for t, s in zip(tasks, scenarios))}"
        + (f"; domain `{Path(domain).name}`" if domain else "")
        + ". Y = a plan that validates and executes in the physics simulation was found with the "
        "primitive removed (`ablate --simulate`), N = none. "
        f"**Bold** with {_DISAGREE}: ours differs from the paper. The paper's table has no baseline row; "
        "it solves both tasks with the full library.", "",
        header,
        "| --- | --- |" + " :---: | :---: |" * len(tasks),
    ]
    for row in rows:
        label = "none (baseline)" if row.removed == BASELINE else row.removed
        cells = " | ".join(f"{format_compared_cell(c)} | {_yn(c.paper)}" for c in row.cells)
        lines.append(f"| {label} | {row.family} | {cells} |")
    known = [c for r in rows for c in r.cells if c.ours is not None and c.paper is not None]
    differ = [(r.removed, tasks[i]) for r in rows for i, c in enumerate(r.cells) if c.disagrees]
    lines += ["", f"{len(known) - len(differ)} of {len(known)} cells agree with the paper"
              + (": differ " + ", ".join(f"without {a} ({t})" for a, t in differ) if differ else "") + "."]
    notes = [(r.removed, tasks[i], c) for r in rows for i, c in enumerate(r.cells)
             if c.ours is not None and c.status not in ("solved", "failed", "")]
    if notes:
        lines += ["", "Not a plain failure to find a plan (the N proves nothing):", ""]
        lines += [f"- without {a}, {t}: {c.status}: {one_line(c.reason)}" for a, t, c in notes]
    found = [(r.removed, tasks[i], c) for r in rows for i, c in enumerate(r.cells) if c.ours]
    if found:
        lines += ["", "Plans found:", ""]
        lines += [f"- {'baseline' if a == BASELINE else f'without {a}'}, {t}: {compress_sequence(c.primitives)}"
                  for a, t, c in found]
    return "\n".join(lines)


def format_figures(figures: Sequence[FigureSet], missing: Mapping[str, str], document: Path,
                   stamp: str) -> str:
    """The ``figures`` block: per task, its snapshots and its contact-state graph; a line
    for each task without figures, saying why."""
    lines = [stamp, "", "Drawn by `ldhp_tamp.render` from the plan files above (PNG only; "
             "`ldhp-tamp render PLAN --scenario SCENARIO` draws the SVGs and the animation too)."]
    for fig in figures:
        lines += ["", f"### `{fig.stem}`"]
        for path in fig.files:
            lines += ["", f"![{fig.stem}: {path.stem.replace('_', ' ')}]({_link(path, document)})"]
        lines += ["", f"_{len(fig.files)} PNG(s) at {fig.dpi} dpi._"]
    for stem, why in missing.items():
        lines += ["", f"### `{stem}`", "", f"No figures: {why}."]
    return "\n".join(lines)


def dirty_paths(porcelain: str, exclude: Sequence[str] = ()) -> tuple[str, ...]:
    """The paths of ``git status --porcelain`` output, without those equal to or under
    one of ``exclude`` (repository-relative, ``/``-separated).

    >>> dirty_paths(" M a.py\\n?? docs/results/x.json\\nR  b -> c\\n", ["docs/results"])
    ('a.py', 'c')
    """
    out = []
    for line in porcelain.splitlines():
        if len(line) < 4:
            continue
        path = line[3:].split(" -> ")[-1].strip('"')
        if not any(path == e or path.startswith(e.rstrip("/") + "/") for e in exclude):
            out.append(path)
    return tuple(out)


# --------------------------------------------------------------------------- doing


def _git(*args: str) -> str | None:
    try:
        done = subprocess.run(["git", *args], cwd=REPO, capture_output=True, text=True, timeout=30, check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout


def run_context(timeout_s: float, grace_s: float, jobs: int, argv: Sequence[str],
                outputs: OutputPaths) -> RunContext:
    """Date, commit and tree state (the files this script writes aside), machine."""
    commit = (_git("rev-parse", "--short", "HEAD") or "").strip() or "unknown"
    status = _git("status", "--porcelain")
    exclude = []
    for p in (outputs.document, outputs.results):
        try:
            exclude.append(p.resolve().relative_to(REPO).as_posix())
        except ValueError:
            pass  # outside the repository: git does not see it
    return RunContext(
        date=datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        commit=commit,
        dirty=None if status is None else dirty_paths(status, exclude),
        cpus=os.cpu_count(), python=platform.python_version(), platform=platform.platform(),
        timeout_s=timeout_s, grace_s=grace_s, jobs=jobs,
        command=shlex.join([".venv/bin/python", SCRIPT, *argv]))


def _validate(plan_file: Path, scenario_file: Path) -> tuple[bool, tuple[str, ...], tuple[str, ...]]:
    """Read a plan back and validate it: (valid, its primitives, the problems)."""
    plan = read_plan(plan_file)
    primitives = tuple(step.primitive for step in plan.steps)
    report = validate_plan(plan, load_scenario(scenario_file))
    problems = tuple(format_violation(v, plan) for v in report.violations[:MAX_VIOLATIONS])
    if len(report.violations) > MAX_VIOLATIONS:
        problems += (f"and {len(report.violations) - MAX_VIOLATIONS} more violation(s)",)
    return report.valid, primitives, problems


def run_suite(stems: Sequence[str], outputs: OutputPaths, options: BenchOptions) -> tuple[SuiteEntry, ...]:
    """One harness run per scenario, its plan kept and validated again."""
    outputs.plans.mkdir(parents=True, exist_ok=True)
    files = [SCENARIOS / f"{stem}.toml" for stem in stems]
    specs = tuple(replace(spec, plan_file=str(outputs.plan(stem)))
                  for spec, stem in zip(plan_runs(files, options), stems, strict=True))
    for stem in stems:  # an old plan must not pass for this run's
        outputs.plan(stem).unlink(missing_ok=True)

    def on_row(done: int, row: BenchRow) -> None:
        t = f"{row.time_total_s:.2f} s" if row.time_total_s is not None else f"{row.wall_s:.2f} s wall"
        log.info("suite [%d/%d] %s: %s (%s)", done, len(specs), row.scenario, row.status.value, t)

    log.info("suite: %d scenario(s), %d at a time", len(specs), options.jobs)
    rows = run_all(specs, options, on_row)
    entries = []
    for stem, path, row in zip(stems, files, rows, strict=True):
        plan_file = outputs.plan(stem)
        if not plan_file.is_file():
            entries.append(SuiteEntry(stem, row, None, (), None))
            continue
        if row.status is not BenchStatus.SOLVED:
            entries.append(SuiteEntry(stem, row, plan_file, tuple(s.primitive for s in read_plan(plan_file).steps),
                                      None))
            continue
        valid, primitives, problems = _validate(plan_file, path)
        if not valid:
            log.warning("suite: %s: the plan does not validate: %s", stem, "; ".join(problems))
        entries.append(SuiteEntry(stem, row, plan_file, primitives, valid, problems))
    return tuple(entries)


def run_ablation(outputs: OutputPaths, timeout_s: float, jobs: int) -> AblationTable:
    """Table III on task 1 and task 2; the CSV written."""
    files = [SCENARIOS / f"{stem}.toml" for stem in ABLATION_STEMS]
    table = ablate(files, AblationOptions(timeout_s=timeout_s, jobs=jobs, simulate=True),
                   progress=lambda msg: log.info("ablation %s", msg))
    outputs.results.mkdir(parents=True, exist_ok=True)
    write_csv(table, outputs.ablation_csv)
    return table


def render_pngs(plan_file: Path, scenario_file: Path, out_dir: Path,
                dpis: Sequence[int] = FIGURE_DPIS, limit: int = PNG_LIMIT_BYTES) -> FigureSet:
    """Render a plan (in a temporary folder) and keep only :data:`FIGURE_PNGS` in
    ``out_dir``, at the first resolution of ``dpis`` at which each is below ``limit``
    bytes (the last one otherwise, with a warning)."""
    # The render also draws the SVGs and the GIF: a tiny animation costs little.
    with tempfile.TemporaryDirectory(prefix="ldhp-results-") as tmp:
        for dpi in dpis:
            render_files(plan_file, scenario_file, tmp, RenderOptions(dpi=dpi, max_frames=2, gif_width=64))
            blobs = {name: (Path(tmp) / name).read_bytes() for name in FIGURE_PNGS}
            if max(len(b) for b in blobs.values()) < limit:
                break
        else:
            log.warning("figures of %s: a PNG is %d bytes even at %d dpi", plan_file.name,
                        max(len(b) for b in blobs.values()), dpis[-1])
    out_dir.mkdir(parents=True, exist_ok=True)
    written = tuple(write_bytes_atomic(out_dir / name, blob) for name, blob in blobs.items())
    return FigureSet(out_dir.name, written, dpi)


def run_figures(entries: Sequence[SuiteEntry], outputs: OutputPaths
                ) -> tuple[tuple[FigureSet, ...], dict[str, str]]:
    """Figures of the tasks of :data:`FIGURE_STEMS` that were run: drawn for a solved,
    validated plan; otherwise the reason there are none."""
    by_stem = {e.stem: e for e in entries}
    figures, missing = [], {}
    for stem in FIGURE_STEMS:
        entry = by_stem.get(stem)
        if entry is None:
            continue
        if entry.plan_file is None or not entry.validated:
            missing[stem] = f"the run is {entry.row.status.value}" + (
                ", and its plan does not validate" if entry.validated is False else "")
            for name in FIGURE_PNGS:  # an old plan's figures must not pass for this run's
                (outputs.figures / stem / name).unlink(missing_ok=True)
            continue
        log.info("figures: %s", stem)
        figures.append(render_pngs(entry.plan_file, SCENARIOS / f"{stem}.toml", outputs.figures / stem))
    return tuple(figures), missing


# --------------------------------------------------------------------------- command line


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line message (no usage) and exit status 2 on bad input."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message}\n")


def _positive_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number of seconds, got {text!r}")
    return value


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected at least 1, got {text!r}")
    return value


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="results.py",
                description="Regenerate docs/results.md: the scenario suite, the paper's Table III, figures.",
                epilog="exit status: 0 it ran (whatever the solves' outcomes), 2 bad input")
    p.add_argument("--timeout", type=_positive_seconds, default=DEFAULT_TIMEOUT_S, metavar="S",
                   help=f"seconds per solve, suite and ablation (default {DEFAULT_TIMEOUT_S:g})")
    p.add_argument("--jobs", type=_positive_int, default=1, metavar="J",
                   help="solves at once, each in a worker process (default 1)")
    p.add_argument("--out", type=Path, default=DEFAULT_OUT, metavar="FILE",
                   help="the document to update (default docs/results.md); plans, figures and the CSV "
                        "go into the folder of the same name beside it")
    p.add_argument("--only", metavar="NAME,...",
                   help="run and list only these scenarios (stems of scenarios/*.toml); the suite table "
                        "then has only their rows; for quick checks")
    p.add_argument("--skip-ablation", action="store_true", help="keep the ablation block as it is")
    p.add_argument("--skip-figures", action="store_true", help="keep the figures block as it is")
    return p


def shipped_stems() -> tuple[str, ...]:
    return tuple(sorted(p.stem for p in SCENARIOS.glob("*.toml")))


def select_stems(only: str | None, known: Sequence[str]) -> tuple[str, ...]:
    """The stems to run: all of ``known``, or those of the comma-separated ``only``.

    Raises
    ------
    InputError
        An ``only`` name that is not a known stem, or no name at all.
    """
    if only is None:
        return tuple(known)
    wanted = tuple(dict.fromkeys(n.strip() for n in only.split(",") if n.strip()))
    if not wanted:
        raise InputError(f"--only: expected comma-separated scenario names, got {only!r}")
    unknown = [n for n in wanted if n not in known]
    if unknown:
        raise InputError(f"--only: no scenario {unknown[0]!r} in scenarios/ (known: {', '.join(known)})")
    return wanted


def _check_out(path: Path) -> None:
    if path.is_dir():
        raise InputError(f"{path}: --out must be a Markdown file, and this is a folder")
    if not path.parent.is_dir():
        raise InputError(f"{path}: --out: no such folder: {path.parent}")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the suite (and the ablation, the figures), then update the document."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(args_list)
    try:
        stems = select_stems(args.only, shipped_stems())
        outputs = OutputPaths.of(args.out)
        _check_out(args.out)
        read_document(args.out)  # a missing marker fails now, not after an hour of solving
        bench_options = BenchOptions(timeout_s=args.timeout, jobs=args.jobs, judge_simulate=True)
        ctx = run_context(args.timeout, bench_options.grace_s, args.jobs, args_list, outputs)

        blocks: dict[str, str] = {}
        entries = run_suite(stems, outputs, bench_options)
        blocks["suite"] = format_suite(entries, args.out, ctx.stamp)
        blocks["suite-details"] = format_suite_details(entries, ctx.stamp)
        table = None
        if not args.skip_ablation:
            table = run_ablation(outputs, args.timeout, args.jobs)
            blocks["ablation"] = format_ablation(compare_with_paper(table), table.scenarios, ctx.stamp,
                                                 table.domain)
        if not args.skip_figures:
            figures, missing = run_figures(entries, outputs)
            if figures or missing:
                blocks["figures"] = format_figures(figures, missing, args.out, ctx.stamp)
            else:
                log.info("figures: neither %s was run: the figures block is kept", " nor ".join(FIGURE_STEMS))
        done = ["context", *blocks]
        blocks["context"] = format_context(ctx, done, [b for b in BLOCKS if b not in done])
        text = replace_blocks(read_document(args.out), blocks, str(args.out))  # re-read: edits meanwhile
        write_text_atomic(args.out, text)
    except InputError as exc:
        print(f"results.py: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"results.py: error: cannot write the results: {exc}", file=sys.stderr)
        return 2

    solved = sum(e.row.status is BenchStatus.SOLVED for e in entries)
    print(f"suite: {solved}/{len(entries)} solved, {sum(e.validated is True for e in entries)} validated")
    if table is not None:
        rows = compare_with_paper(table)
        differ = sum(c.disagrees for r in rows for c in r.cells)
        print(f"ablation: {differ} cell(s) differ from the paper; wrote {outputs.ablation_csv}")
    print(f"wrote {args.out} ({', '.join(done)})")
    return 0


if __name__ == "__main__":
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr)
    log.setLevel(logging.INFO)
    sys.exit(main())
