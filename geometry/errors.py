"""Exceptions of the geometric backend.

``geometry`` never imports ``ldhp_tamp``; the planner wraps these into its own exception
tree where it needs file names and keys in the message.
"""

from __future__ import annotations


class GeometryError(ValueError):
    """Invalid geometric input (degenerate or self-intersecting polygon, bad limits...)."""
