"""Contacts between object and environment features, and contact states.

A *principal contact* (after Xiao & Ji) pairs one object feature with one environment
feature: vertex-edge (object vertex on an environment edge, ``v2-e1``), edge-vertex
(environment vertex on an object edge, ``l3-ve4``) or edge-edge (an object edge lying
flush on an environment edge, ``l1-e1``). An edge-edge contact subsumes the vertex-edge
and edge-vertex contacts it implies. A *contact state* is the set of principal contacts
present at a pose; the empty state is ``free``.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass


class ContactKind(enum.Enum):
    VERTEX_EDGE = "vertex-edge"  # object vertex on environment edge
    EDGE_VERTEX = "edge-vertex"  # environment vertex on object edge
    EDGE_EDGE = "edge-edge"  # object edge flush on environment edge


_OBJ_PREFIX = {ContactKind.VERTEX_EDGE: "v", ContactKind.EDGE_VERTEX: "l", ContactKind.EDGE_EDGE: "l"}
_ENV_PREFIX = {ContactKind.VERTEX_EDGE: "e", ContactKind.EDGE_VERTEX: "ve", ContactKind.EDGE_EDGE: "e"}
_NAME = re.compile(r"^(v|l)(\d+)-(e|ve)(\d+)$")


@dataclass(frozen=True)
class Contact:
    """One principal contact; indices are 0-based, names 1-based."""

    kind: ContactKind
    obj: int
    env: int

    def sort_key(self) -> tuple[int, int, str]:
        return (self.env, self.obj, self.kind.value)

    @property
    def name(self) -> str:
        return f"{_OBJ_PREFIX[self.kind]}{self.obj + 1}-{_ENV_PREFIX[self.kind]}{self.env + 1}"

    @classmethod
    def parse(cls, name: str) -> "Contact":
        """Inverse of :attr:`name` (``v2-e1``, ``l3-ve4``, ``l1-e1``)."""
        m = _NAME.match(name.strip().lower())
        if not m:
            raise ValueError(f"not a contact name: {name!r}")
        o, i, e, j = m.group(1), int(m.group(2)) - 1, m.group(3), int(m.group(4)) - 1
        if o == "v" and e == "e":
            kind = ContactKind.VERTEX_EDGE
        elif o == "l" and e == "ve":
            kind = ContactKind.EDGE_VERTEX
        elif o == "l" and e == "e":
            kind = ContactKind.EDGE_EDGE
        else:
            raise ValueError(f"a vertex cannot touch a vertex as a principal contact: {name!r}")
        return cls(kind, i, j)

    def __str__(self) -> str:
        return self.name


@dataclass(frozen=True)
class ContactState:
    """A set of principal contacts, kept sorted. ``ContactState(())`` is ``free``."""

    contacts: tuple[Contact, ...]

    @classmethod
    def of(cls, contacts) -> "ContactState":
        return cls(tuple(sorted(set(contacts), key=Contact.sort_key)))

    @classmethod
    def parse(cls, name: str) -> "ContactState":
        if name.strip().lower() == "free":
            return FREE
        return cls.of(Contact.parse(p) for p in name.split("+"))

    @property
    def is_free(self) -> bool:
        return not self.contacts

    @property
    def name(self) -> str:
        """Human name: ``free``, ``l1-e1`` or ``v2-e1+v3-e4``."""
        return "+".join(c.name for c in self.contacts) if self.contacts else "free"

    @property
    def pddl_name(self) -> str:
        """A PDDL-safe object name: ``s-free``, ``s-l1-e1``, ``s-v2-e1_v3-e4``."""
        return "s-" + ("_".join(c.name for c in self.contacts) if self.contacts else "free")

    def __len__(self) -> int:
        return len(self.contacts)

    def __str__(self) -> str:
        return self.name


FREE = ContactState(())
