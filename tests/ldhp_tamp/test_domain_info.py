"""The light domain reader of the validator (rule 0) agrees with the symbolic tier."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from ldhp_tamp.domain_info import parse_domain_actions, parse_sexprs, read_domain_actions
from ldhp_tamp.errors import DomainError
from ldhp_tamp.primitives.registry import Family
from ldhp_tamp.resources import domains_dir

ROOT = Path(__file__).resolve().parents[2]
FILES = sorted(domains_dir().glob("*.pddl")) + sorted((ROOT / "tests" / "data" / "domains").glob("*.pddl"))


@pytest.mark.parametrize("path", FILES, ids=[p.name for p in FILES])
def test_families_agree_with_the_symbolic_tier(path: Path) -> None:
    """Where unified-planning reads the domain, the same actions, in the same order, with
    the same families; where it refuses a syntax error, so does this reader."""
    from ldhp_tamp.symbolic import load_domain

    try:
        symbolic = load_domain(path)
    except DomainError as exc:
        if "PDDL error" in str(exc):
            with pytest.raises(DomainError, match=path.name):
                read_domain_actions(path)
        else:  # a convention of the planner: the light reader still reads the actions
            assert read_domain_actions(path).names()
        return
    light = read_domain_actions(path)
    assert light.actions == tuple((a.name, a.family) for a in symbolic.info.actions)
    assert light.name == symbolic.info.name


def test_the_shipped_domain() -> None:
    d = read_domain_actions(domains_dir() / "ldhp.pddl")
    assert d.names(Family.MOVE_OBJECT) == ("tip", "push", "biplanar-slide", "air-move")
    assert set(d.names(Family.ADJUST_GRASP)) == {"open", "close", "pivot", "slide", "flip", "approach-contact"}
    assert read_domain_actions(domains_dir() / "ldhp.pddl") is d  # cached while unchanged


def test_effects_inside_when_forall_and_not_count() -> None:
    text = """(define (domain d) (:predicates (at ?s) (p))
      (:action a :parameters (?x) :effect (when (p) (not (at ?x))))
      (:action b :parameters (?x) :effect (forall (?y) (and (p) (at ?y))))
      (:action c :effect (and (p) (increase (total-cost) 1)))
      (:action d :precondition (at ?x) :effect (p)))"""
    d = parse_domain_actions(text)
    assert [f for _, f in d.actions] == [Family.MOVE_OBJECT, Family.MOVE_OBJECT, Family.ADJUST_GRASP, Family.ADJUST_GRASP]


@pytest.mark.parametrize("text, fragment", [
    ("(define (domain d) (:action a :effect (p))", "never closed"),
    ("(define (domain d)))", "without a matching"),
    ("(define (problem d))", "(domain NAME)"),
    ("(define (domain d)) (define (domain e))", "exactly one"),
    ("(define (domain d) (:action :effect (p)))", "needs a name"),
    ("(define (domain d) (:action a :effect (p) :effect (q)))", "given twice"),
    ("(define (domain d) (:action a :cost 3))", "unknown key"),
    ("(define (domain d) (:action a :effect (p)) (:action A :effect (q)))", "declared twice"),
    ("(define (domain d) (:durative-action a))", "durative"),
    ("(define (domain d) (:axioms))", "unknown section"),
    ("(define (domain d) (:action a :effect p))", "must be a list"),
])
def test_malformed_domains_are_refused_with_a_line(text: str, fragment: str) -> None:
    with pytest.raises(DomainError, match="x.pddl:1") as exc:
        parse_domain_actions(text, "x.pddl")
    assert fragment in str(exc.value)


def test_comments_and_case() -> None:
    assert parse_sexprs("(A ;; (b\n c)") == [["a", "c"]]
    d = parse_domain_actions("(define (DOMAIN Tiny) ; x\n (:ACTION Go :EFFECT (AT ?x)))")
    assert d.name == "tiny" and d.family("GO") is Family.MOVE_OBJECT


def test_reading_a_domain_does_not_import_unified_planning() -> None:
    code = ("import sys; from ldhp_tamp.validate import domain_actions; "
            "from ldhp_tamp.domain_info import read_domain_actions; from ldhp_tamp.resources import domains_dir; "
            "read_domain_actions(domains_dir() / 'ldhp.pddl'); "
            "assert 'unified_planning' not in sys.modules and 'scipy' not in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)
