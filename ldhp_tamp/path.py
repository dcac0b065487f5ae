"""Object-pose paths: the values the top tier hands to the bottom tier.

A :class:`Segment` is one MoveObject primitive instance m_k: a motion family of
:mod:`geometry.kinematics` with the parameter interval it covers, the contact states at
its ends, the primitive's parameters as they appear in a plan, and its dense pose samples
(no object vertex moves more than ``WAYPOINT_STEP`` between samples). A pose path
T_0..T_n is a tuple of segments whose ends join.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any, Mapping

import numpy as np

from geometry.contacts import contact_state
from geometry.features import ContactState
from geometry.kinematics import Motion, MotionKind, dense_parameters
from geometry.poses import FloatArray, Pose
from geometry.tolerances import WAYPOINT_STEP
from geometry.world import World


#: MoveObject primitives whose segments the bottom tier may bisect (paper: dichotomy
#: refinement of contact-sensitive segments).
REFINABLE = frozenset({"tip", "biplanar-slide"})


@dataclass(frozen=True, eq=False)
class Segment:
    """One MoveObject primitive instance: ``motion`` from parameter ``s0`` to ``s1``."""

    primitive: str
    from_state: ContactState
    to_state: ContactState
    motion: Motion
    s0: float
    s1: float
    world: World = field(repr=False)
    parameters: Mapping[str, Any] = field(default_factory=dict)
    depth: int = 0  # how many bisections produced this segment
    step: int = -1  # index of the planned symbolic transition this segment realises
    parent: "Segment | None" = field(default=None, repr=False)
    """The segment a bisection cut this one from; its dense samples are then a slice of
    the parent's (``span``), so what was learnt of the parent carries over."""
    span: tuple[int, int] | None = None  # (first, last) index into the parent's samples
    turn_step: float | None = None
    """For a rotation (``s`` an angle): the largest turn (radians) between samples, on top
    of the vertex step. An air-move's turn sets it: the grasp must hold the object at every
    orientation, and a small object's vertices move little per degree."""

    @cached_property
    def parameter_values(self) -> FloatArray:
        if self.parent is not None and self.span is not None:
            return self.parent.parameter_values[self.span[0]:self.span[1] + 1]
        values = dense_parameters(self.world, self.motion, self.s0, self.s1, WAYPOINT_STEP)
        if self.turn_step is not None and self.motion.kind is MotionKind.ROTATE:
            n = max(1, int(math.ceil(abs(self.s1 - self.s0) / self.turn_step)))
            values = np.union1d(values, np.linspace(self.s0, self.s1, n + 1))
        return values

    @cached_property
    def poses(self) -> FloatArray:
        """Dense object poses (J + 1, 3) from the start to the end of the segment."""
        if self.parent is not None and self.span is not None:
            return self.parent.poses[self.span[0]:self.span[1] + 1]
        p = self.motion.poses(self.parameter_values)
        p.setflags(write=False)
        return p

    @property
    def start(self) -> Pose:
        return Pose.from_array(self.poses[0])

    @property
    def end(self) -> Pose:
        return Pose.from_array(self.poses[-1])

    @property
    def refinable(self) -> bool:
        """A contact-sensitive segment (``tip``, ``biplanar-slide``) with a sample to cut at."""
        return self.primitive in REFINABLE and self.parameter_values.size >= 3

    def split(self, at: int | None = None, *, value: float | None = None) -> tuple["Segment", "Segment"]:
        """Bisect the parameter range (paper: dichotomy refinement).

        The cut is the dense sample nearest the middle of the range (at most half a
        waypoint step, 2 mm of vertex motion, from it), or sample ``at`` when given (an
        interior sample), so the halves' samples are the parent's own: its first
        ``i + 1`` and its last ``J - i + 1``.

        With ``value`` (a parameter strictly between ``s0`` and ``s1`` that is no sample,
        e.g. a rest window narrower than the samples' spacing) the cut is there instead:
        the halves keep ``self`` as their parent (for the refinement count) but take
        dense samples of their own, ending and starting exactly at the cut.
        """
        if value is not None:
            lo, hi = sorted((self.s0, self.s1))
            if not lo < value < hi:
                raise ValueError(f"cut {value} is not inside the parameter range [{lo}, {hi}]")
            cut_state = contact_state(self.world, Pose.from_array(self.motion.poses(np.array([value]))[0]))
            key = "angle" if self.motion.kind is not MotionKind.TRANSLATE else "travel"

            def length(a: float, b: float) -> dict[str, Any]:
                out = dict(self.parameters)
                if key in out:
                    out[key] = math.degrees(abs(b - a)) if key == "angle" else abs(b - a)
                return out

            return (replace(self, to_state=cut_state, s1=value, parameters=length(self.s0, value),
                            depth=self.depth + 1, parent=self, span=None),
                    replace(self, from_state=cut_state, s0=value, parameters=length(value, self.s1),
                            depth=self.depth + 1, parent=self, span=None))
        values = self.parameter_values
        n = values.size
        if n < 3:
            raise ValueError(f"a {self.primitive} segment of {n} samples cannot be bisected")
        if at is None:
            i = int(np.clip(np.argmin(np.abs(values - 0.5 * (self.s0 + self.s1))), 1, n - 2))
        elif 1 <= at <= n - 2:
            i = int(at)
        else:
            raise ValueError(f"cut {at} is not an interior sample of a segment of {n} samples")
        mid = float(values[i])
        mid_state = contact_state(self.world, Pose.from_array(self.poses[i]))
        key = "angle" if self.motion.kind is not MotionKind.TRANSLATE else "travel"

        def params(length: float) -> dict[str, Any]:
            out = dict(self.parameters)
            if key in out:
                out[key] = math.degrees(length) if key == "angle" else length
            return out

        a = replace(self, to_state=mid_state, s1=mid, parameters=params(abs(mid - self.s0)),
                    depth=self.depth + 1, parent=self, span=(0, i))
        b = replace(self, from_state=mid_state, s0=mid, parameters=params(abs(self.s1 - mid)),
                    depth=self.depth + 1, parent=self, span=(i, n - 1))
        return a, b


def check_joined(segments: tuple[Segment, ...], tol: float = 1e-6) -> None:
    """Raise ``ValueError`` unless consecutive segments join (end pose = next start)."""
    for a, b in zip(segments, segments[1:]):
        if not np.allclose(a.poses[-1], b.poses[0], atol=tol):
            raise ValueError(f"segments do not join: {a.primitive} ends at {a.poses[-1]}, "
                             f"{b.primitive} starts at {b.poses[0]}")
