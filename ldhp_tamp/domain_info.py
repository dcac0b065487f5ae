"""A light, strict reader of a PDDL domain's action names and families.

The plan validator needs only which actions a domain declares and the family of each
(rule 0 of ``ldhp-plan/1``); the symbolic tier (:mod:`ldhp_tamp.symbolic`) reads domains
through unified-planning, whose import alone costs seconds. This module reads the same
facts from the file with a tiny s-expression parser (comments, parentheses, atoms; no
regular expressions over the raw text), with the family rule of ``domains/ldhp.pddl``:

- **MoveObject**: an action one of whose effects (positive or negative, also inside
  ``when`` and ``forall``) names the predicate ``at``;
- **AdjustGrasp**: every other action.

It checks the structure it reads (one ``(define (domain NAME) ...)``, balanced
parentheses, sections that are lists headed by a known keyword, each action with a name
and at most one ``:parameters``, ``:precondition`` and ``:effect``, no duplicate action)
and nothing else: the symbolic tier's conventions (``can-*`` predicates, the problem
vocabulary) are the planner's business. A test checks that both readers give the same
families on every domain file the project ships or tests with.

Examples
--------
>>> d = parse_domain_actions('''(define (domain tiny) (:requirements :strips)
...   (:predicates (at ?s) (touching))
...   (:action Move :parameters (?a ?b) :precondition (at ?a)
...     :effect (and (not (at ?a)) (at ?b)))
...   (:action grab :parameters () :effect (touching)))''')
>>> d.name, d.names()
('tiny', ('move', 'grab'))
>>> d.family("move").value, d.family("GRAB").value, d.family("fly")
('move-object', 'adjust-grasp', None)
"""

from __future__ import annotations

import functools
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Union

from ldhp_tamp.errors import DomainError
from ldhp_tamp.primitives.registry import Family

__all__ = ["DomainActions", "SExpr", "parse_domain_actions", "parse_sexprs", "read_domain_actions"]

log = logging.getLogger(__name__)

#: The predicate whose change makes an action a MoveObject primitive.
AT = "at"

#: An s-expression: an atom (lower-cased) or a list of s-expressions.
SExpr = Union[str, "SList"]


class SList(list):  # type: ignore[type-arg]
    """A parenthesised list of s-expressions, with the line where it opens."""

    line: int = 0


#: Sections of a ``define`` that may appear, beside ``(domain NAME)`` and ``:action``.
_SECTIONS = frozenset({":requirements", ":types", ":constants", ":predicates", ":functions"})
#: Sections that would make actions the reader cannot describe (the symbolic tier
#: refuses them too).
_UNSUPPORTED = {":durative-action": "a durative action", ":derived": "a derived predicate",
                ":process": "a process", ":event": "an event", ":constraints": "trajectory constraints"}
#: Keys of an ``:action`` list.
_ACTION_KEYS = frozenset({":parameters", ":precondition", ":effect"})
#: Numeric effects: their first argument is a function term, not a predicate.
_NUMERIC = frozenset({"increase", "decrease", "assign", "scale-up", "scale-down"})


@dataclass(frozen=True)
class DomainActions:
    """The actions of a PDDL domain with their families, in file order.

    Attributes
    ----------
    name : str
        The domain's name, lower case.
    source : str
        Where it was read from (a path or ``"<string>"``).
    actions : tuple of (str, Family)
        Each action's name (lower case, as PDDL reads it) and family.
    """

    name: str
    source: str
    actions: tuple[tuple[str, Family], ...]

    def names(self, family: Family | None = None) -> tuple[str, ...]:
        """Action names in file order, optionally of one family only."""
        return tuple(n for n, f in self.actions if family is None or f is family)

    def family(self, action: str) -> Family | None:
        """The family of ``action`` (matched case-insensitively, as PDDL does), or
        ``None`` if the domain declares no such action."""
        key = action.lower()
        for n, f in self.actions:
            if n == key:
                return f
        return None


# --------------------------------------------------------------------------------------
# S-expressions
# --------------------------------------------------------------------------------------


def _fail(source: str, line: int, problem: str) -> DomainError:
    return DomainError(f"{source}:{line}: PDDL error: {problem}")


def parse_sexprs(text: str, source: str = "<string>") -> list[SExpr]:
    """The top-level s-expressions of ``text``: atoms lower-cased, ``;`` comments dropped.

    Raises
    ------
    DomainError
        An unbalanced parenthesis, with the file and line.

    Examples
    --------
    >>> parse_sexprs("(a (B c)) ; note\\n d")
    [['a', ['b', 'c']], 'd']
    """
    top: list[SExpr] = []
    stack: list[SList] = []
    line = 1
    i, n = 0, len(text)
    while i < n:
        ch = text[i]
        if ch == "\n":
            line += 1
            i += 1
        elif ch.isspace():
            i += 1
        elif ch == ";":
            while i < n and text[i] != "\n":
                i += 1
        elif ch == "(":
            lst = SList()
            lst.line = line
            stack.append(lst)
            i += 1
        elif ch == ")":
            if not stack:
                raise _fail(source, line, "')' without a matching '('")
            done = stack.pop()
            (stack[-1] if stack else top).append(done)
            i += 1
        else:
            j = i
            while j < n and not text[j].isspace() and text[j] not in "();":
                j += 1
            (stack[-1] if stack else top).append(text[i:j].lower())
            i = j
    if stack:
        raise _fail(source, stack[-1].line, "'(' never closed")
    return top


# --------------------------------------------------------------------------------------
# Domains
# --------------------------------------------------------------------------------------


def _changed(effect: SExpr, source: str, line: int) -> set[str]:
    """Predicates (and numeric functions) an effect expression names."""
    if isinstance(effect, str):
        raise _fail(source, line, f"an effect must be a list, got {effect!r}")
    if not effect:
        return set()
    head = effect[0]
    if not isinstance(head, str):
        raise _fail(source, getattr(effect, "line", line), "an effect list must start with a name")
    at = getattr(effect, "line", line)
    if head == "and":
        out: set[str] = set()
        for part in effect[1:]:
            out |= _changed(part, source, at)
        return out
    if head == "not":
        if len(effect) != 2:
            raise _fail(source, at, "(not ...) takes one argument")
        return _changed(effect[1], source, at)
    if head == "when":
        if len(effect) != 3:
            raise _fail(source, at, "(when CONDITION EFFECT) takes two arguments")
        return _changed(effect[2], source, at)
    if head == "forall":
        if len(effect) != 3 or isinstance(effect[1], str):
            raise _fail(source, at, "(forall (VARIABLES) EFFECT) takes two arguments")
        return _changed(effect[2], source, at)
    if head in _NUMERIC:
        if len(effect) != 3 or isinstance(effect[1], str) or not effect[1] or not isinstance(effect[1][0], str):
            raise _fail(source, at, f"({head} (FUNCTION ...) VALUE) takes a function and a value")
        return {effect[1][0]}
    if head.startswith((":", "?")):
        raise _fail(source, at, f"{head!r} is not a predicate")
    return {head}


def _action(expr: SList, source: str) -> tuple[str, Family]:
    line = expr.line
    if len(expr) < 2 or not isinstance(expr[1], str) or expr[1].startswith(":"):
        raise _fail(source, line, "(:action NAME ...) needs a name")
    name = expr[1]
    seen: dict[str, SExpr] = {}
    rest = expr[2:]
    if len(rest) % 2:
        raise _fail(source, line, f"action {name!r}: keys and values do not pair up")
    for key, value in zip(rest[::2], rest[1::2]):
        if not isinstance(key, str) or key not in _ACTION_KEYS:
            raise _fail(source, line, f"action {name!r}: unknown key {key!r} "
                        f"(expected {', '.join(sorted(_ACTION_KEYS))})")
        if key in seen:
            raise _fail(source, line, f"action {name!r}: {key} given twice")
        if isinstance(value, str):
            raise _fail(source, line, f"action {name!r}: {key} must be a list, got {value!r}")
        seen[key] = value
    effect = seen.get(":effect")
    changed = _changed(effect, source, line) if effect is not None else set()
    return name, Family.MOVE_OBJECT if AT in changed else Family.ADJUST_GRASP


def parse_domain_actions(text: str, source: str = "<string>") -> DomainActions:
    """Read a domain's action names and families from PDDL text.

    Raises
    ------
    DomainError
        Naming ``source`` and a line: unbalanced parentheses, no single
        ``(define (domain NAME) ...)``, an unknown or unsupported section, a malformed
        action, or an action declared twice.
    """
    exprs = parse_sexprs(text, source)
    if len(exprs) != 1 or isinstance(exprs[0], str) or not exprs[0] or exprs[0][0] != "define":
        raise _fail(source, 1, "expected exactly one (define (domain NAME) ...)")
    define = exprs[0]
    head = define[1] if len(define) > 1 else None
    if (not isinstance(head, list) or len(head) != 2 or head[0] != "domain"
            or not isinstance(head[1], str)):
        raise _fail(source, define.line, "(define ...) must start with (domain NAME)")
    actions: list[tuple[str, Family]] = []
    for section in define[2:]:
        if isinstance(section, str) or not section or not isinstance(section[0], str):
            raise _fail(source, getattr(section, "line", define.line), f"unexpected {section!r} in the domain")
        kind = section[0]
        if kind == ":action":
            action = _action(section, source)
            if any(action[0] == a for a, _ in actions):
                raise _fail(source, section.line, f"action {action[0]!r} is declared twice")
            actions.append(action)
        elif kind in _UNSUPPORTED:
            raise _fail(source, section.line, f"{_UNSUPPORTED[kind]} ({kind}) is not supported: "
                        "actions must be instantaneous")
        elif kind not in _SECTIONS:
            raise _fail(source, section.line, f"unknown section {kind!r}")
    return DomainActions(head[1], source, tuple(actions))


@functools.lru_cache(maxsize=16)
def _read_cached(path: str, mtime_ns: int, size: int) -> DomainActions:
    try:
        text = Path(path).read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise DomainError(f"{path}: cannot read domain: {exc}") from exc
    log.debug("read the actions of domain %s", path)
    return parse_domain_actions(text, source=path)


def read_domain_actions(path: str | os.PathLike[str]) -> DomainActions:
    """:func:`parse_domain_actions` of a file; cached while the file is unchanged
    (same path, modification time and size), so repeated validations read it once.

    Raises
    ------
    DomainError
        An unreadable file, or what :func:`parse_domain_actions` raises.
    """
    p = str(Path(path).resolve())
    try:
        st = os.stat(p)
    except OSError as exc:
        raise DomainError(f"{path}: cannot read domain: {exc}") from exc
    return _read_cached(p, st.st_mtime_ns, st.st_size)
