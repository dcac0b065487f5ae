"""Principal contacts at a pose, their contact geometry, and contact-state enumeration.

Three parts, in the order data flows:

1. **Identification** (:func:`principal_contact_masks`, :func:`principal_contacts`,
   :func:`contact_state`): which principal contacts (after Xiao & Ji) hold at an object
   pose, at one contact tolerance ``tol`` (default :data:`CONTACT_TOL`). Vectorised over
   poses x object features x environment features.
2. **Contact geometry** (:func:`contact_points`): the point contacts a mechanics test needs
   (world point, unit normal into the object, friction coefficient).
3. **Enumeration** (:func:`enumerate_contact_states`): the single and two-contact states
   that some non-penetrating pose realises near the task (:class:`Workspace`), each with a
   few diverse witness poses. These are the nodes of the paper's top-tier graph.

Definitions (``tol`` = contact tolerance; ``n_j`` the outward normal of environment edge
``e_j``, pointing into free space; ``n_i`` the outward normal of object edge ``l_i``):

- **vertex-edge** ``v_i-e_j``: the object vertex ``v_i`` is convex and within ``tol`` of the
  segment ``e_j``, and the object is locally on the free side of ``e_j``: both object edges
  leaving ``v_i`` point into the free half-plane, ``n_j . d >= -tol / |l|`` (each edge's far
  end is at most ``tol`` below the line through ``v_i``).
- **edge-vertex** ``l_i-ve_k``: the environment vertex ``ve_k`` is convex and within ``tol``
  of the segment ``l_i``, and the environment is locally on the outer side of ``l_i``: both
  environment edges leaving ``ve_k`` satisfy ``n_i . d >= -tol / |e|``. A concave (or
  straight) environment vertex is never an edge-vertex contact.
- **edge-edge** ``l_i-e_j``: the edges face each other (``n_i . n_j < 0``), the projection
  of ``l_i`` on ``e_j`` overlaps ``e_j`` over a length ``> tol``, and at both ends of that
  overlap the object edge is within ``tol`` of the line of ``e_j``. This bounds the angle
  between the edges by ``|sin a| <= 2 tol / overlap``: "antiparallel within ``tol`` over the
  contact length". It subsumes the vertex-edge contacts of ``l_i``'s end vertices on
  ``e_j`` and the edge-vertex contacts of ``e_j``'s end vertices on ``l_i``.

A vertex touching a vertex is not a principal contact: it shows as the vertex-edge and/or
edge-vertex contacts whose side conditions hold (at least one always does for two convex
corners that do not overlap).
"""

from __future__ import annotations

import logging
import math
import weakref
from dataclasses import dataclass

import numpy as np
import shapely
from numpy.typing import ArrayLike, NDArray

from geometry.collision import eroded_environment, object_env_overlap
from geometry.compiled import KERNELS
from geometry.features import Contact, ContactKind, ContactState
from geometry.poses import BoolArray, IntArray, Pose, transform_points, wrap_angle
from geometry.shapes import FloatArray
from geometry.tolerances import CONTACT_TOL, EPS, PENETRATION_TOL
from geometry.world import World

__all__ = [
    "ContactMasks",
    "ContactPoints",
    "Workspace",
    "RelevantFeatures",
    "StateWitness",
    "principal_contact_masks",
    "rests_alone",
    "principal_contacts",
    "contact_state",
    "contact_points",
    "workspace_for_task",
    "relevant_features",
    "enumerate_contact_states",
    "row_groups",
]

logger = logging.getLogger(__name__)



# ======================================================================================
# 1. Identification
# ======================================================================================


@dataclass(frozen=True, eq=False)
class ContactMasks:
    """Principal contacts of a batch of poses, as boolean masks.

    Attributes
    ----------
    vertex_edge : ndarray of bool, (B, N, M)
        ``[b, i, j]``: object vertex ``i`` on environment edge ``j``.
    edge_vertex : ndarray of bool, (B, N, M)
        ``[b, i, k]``: environment vertex ``k`` on object edge ``i``.
    edge_edge : ndarray of bool, (B, N, M)
        ``[b, i, j]``: object edge ``i`` flush on environment edge ``j``.
    """

    vertex_edge: BoolArray
    edge_vertex: BoolArray
    edge_edge: BoolArray

    @property
    def counts(self) -> IntArray:
        """(B,) number of principal contacts at each pose."""
        return (self.vertex_edge.sum(axis=(1, 2)) + self.edge_vertex.sum(axis=(1, 2))
                + self.edge_edge.sum(axis=(1, 2)))

    def contacts(self, b: int) -> tuple[Contact, ...]:
        """The principal contacts of pose ``b``, sorted as in :class:`ContactState`."""
        out = [Contact(ContactKind.VERTEX_EDGE, int(i), int(j)) for i, j in np.argwhere(self.vertex_edge[b])]
        out += [Contact(ContactKind.EDGE_VERTEX, int(i), int(k)) for i, k in np.argwhere(self.edge_vertex[b])]
        out += [Contact(ContactKind.EDGE_EDGE, int(i), int(j)) for i, j in np.argwhere(self.edge_edge[b])]
        return tuple(sorted(out, key=Contact.sort_key))

    def state(self, b: int) -> ContactState:
        """The contact state of pose ``b``."""
        return ContactState(self.contacts(b))


@dataclass(frozen=True, eq=False)
class _Frame:
    """World geometry of the object at a batch of poses, and its relation to the solids."""

    V: FloatArray  # (B, N, 2) object vertices
    D: FloatArray  # (B, N, 2) object edge directions
    Nn: FloatArray  # (B, N, 2) object edge outward normals
    u: FloatArray  # (B, N, M) vertex i projected on env edge j (arc length from its start)
    s: FloatArray  # (B, N, M) signed distance of vertex i from the line of env edge j
    masks: ContactMasks
    ee_lo: FloatArray  # (B, N, M) overlap interval of l_i on e_j (arc length on e_j)
    ee_hi: FloatArray


def _rotate(theta: FloatArray, pts: FloatArray) -> FloatArray:
    """Rotate body points (N, 2) by each angle (B,): (B, N, 2)."""
    c = np.cos(theta)[:, None]
    s = np.sin(theta)[:, None]
    return np.stack([c * pts[None, :, 0] - s * pts[None, :, 1], s * pts[None, :, 0] + c * pts[None, :, 1]], axis=-1)


#: The compiled principal-contact tests (:mod:`geometry.compiled`), or None: numpy alone.
_kernels = KERNELS


@dataclass(frozen=True, eq=False)
class _Pairs:
    """The principal-contact tests of object features against environment features,
    laid out as (X, N, Y): axis 1 the object's features, the environment's features
    broadcast along axes 0 and 2 (every edge along axis 2 for a dense frame, one edge
    per row along axis 0 for chosen (pose, edge) pairs). ``ev`` is the environment
    vertex at the start of the edge (vertex ``j`` starts edge ``j``). The subsumption of
    the contacts at an edge-edge contact's ends is left to the caller."""

    u: FloatArray  # vertex i projected on env edge j (arc length from its start)
    s: FloatArray  # signed distance of vertex i from the line of env edge j
    ve: BoolArray
    ev: BoolArray
    ee: BoolArray
    ee_lo: FloatArray  # overlap interval of l_i on e_j (arc length on e_j)
    ee_hi: FloatArray


def _pair_tests(world: World, V: FloatArray, D: FloatArray, Nn: FloatArray, j: IntArray | slice,
                env_shape: tuple[int, ...], tol: float) -> _Pairs:
    """:func:`_pair_tests_numpy`, by the compiled kernel where it is built
    (:mod:`geometry.compiled`: the same operations on the same numbers, the same
    results)."""
    if _kernels is None:
        return _pair_tests_numpy(world, V, D, Nn, j, env_shape, tol)
    poly = world.object.polygon
    X, N = V.shape[:2]
    Xe, Y = env_shape[0], env_shape[2]
    tables, convex = _env_tables(world)
    if not isinstance(j, slice):  # one edge per row
        tables, convex = np.take(tables, j, axis=1), np.take(convex, j)
    shape = (X, N, Y)
    u, s, lo, hi = (np.empty(shape) for _ in range(4))
    ve, ev, ee = (np.empty(shape, dtype=bool) for _ in range(3))
    c = np.ascontiguousarray
    _kernels.pair_tests(c(V, dtype=float), c(D, dtype=float), c(Nn, dtype=float), X, N, Y, c(tables),
                        c(convex).view(np.uint8), Xe, c(poly.edge_lengths, dtype=float),
                        c(poly.convex_vertices).view(np.uint8), float(tol), float(EPS), u, s, lo, hi,
                        ve.view(np.uint8), ev.view(np.uint8), ee.view(np.uint8))
    return _Pairs(u, s, ve, ev, ee, lo, hi)


def _env_tables(world: World) -> tuple[FloatArray, BoolArray]:
    """The environment's tables as the compiled :func:`_pair_tests` reads them (cached per
    world): a (10, M) array of every edge's start vertex (x, y), direction, outward normal
    and length, and the arriving edge's direction and length at its start vertex; and
    the (M,) convexity of the start vertices."""
    hit = _ENV_TABLES.get(world)
    if hit is None:
        env = world.environment
        arrive = env.vertex_edges[:, 0]
        T, Le = env.edge_directions, env.edge_lengths
        tables = np.stack([env.vertices[:, 0], env.vertices[:, 1], T[:, 0], T[:, 1], env.normals[:, 0],
                           env.normals[:, 1], Le, T[arrive, 0], T[arrive, 1], Le[arrive]]).astype(float)
        hit = _ENV_TABLES[world] = (tables, np.ascontiguousarray(env.vertex_convex, dtype=bool))
    return hit


_ENV_TABLES: "weakref.WeakKeyDictionary[World, tuple[FloatArray, BoolArray]]" = weakref.WeakKeyDictionary()


def _pair_tests_numpy(world: World, V: FloatArray, D: FloatArray, Nn: FloatArray, j: IntArray | slice,
                      env_shape: tuple[int, ...], tol: float) -> _Pairs:
    """:class:`_Pairs` of the object at ``V``, ``D``, ``Nn`` ((X, N, 2) each: vertices,
    edge directions, outward normals) against environment edges (and their start
    vertices) ``env.*[j]`` reshaped to ``env_shape`` ((1, 1, M) or (P, 1, 1))."""
    poly = world.object.polygon
    env = world.environment
    n = poly.vertices.shape[0]
    prev = (np.arange(n) - 1) % n  # index shifts instead of np.roll
    nxt = (np.arange(n) + 1) % n
    Lo = poly.edge_lengths
    tol2 = tol * tol
    Vx, Vy, Dx, Dy, Nx, Ny = (a[:, :, None] for a in (V[..., 0], V[..., 1], D[..., 0], D[..., 1], Nn[..., 0], Nn[..., 1]))

    def e(a: NDArray) -> NDArray:  # an environment table, per edge, laid out for broadcasting
        return a[j].reshape(env_shape)

    Ax, Ay = e(env.vertices[:, 0]), e(env.vertices[:, 1])
    Tx, Ty = e(env.edge_directions[:, 0]), e(env.edge_directions[:, 1])
    Nex, Ney = e(env.normals[:, 0]), e(env.normals[:, 1])
    Le = e(env.edge_lengths)
    arrive = env.vertex_edges[:, 0]
    Tax, Tay = e(env.edge_directions[arrive, 0]), e(env.edge_directions[arrive, 1])
    Lea = e(env.edge_lengths[arrive])
    Lo_i = Lo[None, :, None]

    # ---- vertex-edge: object vertex i vs environment edge j -------------------------
    rx = Vx - Ax
    ry = Vy - Ay
    u = rx * Tx + ry * Ty
    s = rx * Nex + ry * Ney
    uc = np.clip(u, 0.0, Le)
    near_ve = (u - uc) ** 2 + s**2 <= tol2
    nd_next = Dx * Nex + Dy * Ney  # d_i . n_j, d_i leaving v_i along l_i
    nd_prev = -nd_next[:, prev]  # -d_(i-1) . n_j, leaving v_i along l_(i-1)
    side_ve = (nd_next >= -tol / Lo_i) & (nd_prev >= -tol / Lo[prev][None, :, None])
    ve = near_ve & side_ve & poly.convex_vertices[None, :, None]

    # ---- edge-vertex: environment vertex k (the start of edge k) vs object edge i ----
    wx = Ax - Vx
    wy = Ay - Vy
    eu = wx * Dx + wy * Dy  # along l_i
    es = wx * Nx + wy * Ny
    euc = np.clip(eu, 0.0, Lo_i)
    near_ev = (eu - euc) ** 2 + es**2 <= tol2
    nt_next = Nx * Tx + Ny * Ty  # n_i . t_k (edge leaving ve_k)
    nt_prev = -(Nx * Tax + Ny * Tay)  # n_i . (-t of the arriving edge)
    side_ev = (nt_next >= -tol / Le) & (nt_prev >= -tol / Lea)
    ev = near_ev & side_ev & e(env.vertex_convex)

    # ---- edge-edge: object edge i (v_i -> v_i+1) vs environment edge j --------------
    uP, sP = u, s
    uQ, sQ = u[:, nxt], s[:, nxt]
    facing = Nx * Nex + Ny * Ney < 0.0
    lo = np.maximum(np.minimum(uP, uQ), 0.0)
    hi = np.minimum(np.maximum(uP, uQ), Le)
    denom = uQ - uP
    ok = facing & (hi - lo > tol) & (np.abs(denom) > EPS)
    safe = np.where(ok, denom, 1.0)
    s_lo = sP + (sQ - sP) * (lo - uP) / safe
    s_hi = sP + (sQ - sP) * (hi - uP) / safe
    ee = ok & (np.abs(s_lo) <= tol) & (np.abs(s_hi) <= tol)
    return _Pairs(u, s, ve, ev, ee, lo, hi)


def _placed(world: World, poses: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The object's world vertices, edge directions and outward normals, (B, N, 2) each."""
    poly = world.object.polygon
    theta = poses[:, 2]
    V = _rotate(theta, poly.vertices) + poses[:, None, :2]
    D = _rotate(theta, poly.edge_directions)
    Nn = np.stack([D[..., 1], -D[..., 0]], axis=-1)
    return V, D, Nn


def _frame(world: World, poses: FloatArray, tol: float) -> _Frame:
    env = world.environment
    n = world.object.n
    prev = (np.arange(n) - 1) % n
    V, D, Nn = _placed(world, poses)
    pr = _pair_tests(world, V, D, Nn, slice(None), (1, 1, env.m), tol)
    # ---- subsumption: an edge-edge contact absorbs the contacts at its overlap ends --
    ee, arrive = pr.ee, env.vertex_edges[:, 0]
    ve = pr.ve & ~ee & ~ee[:, prev]  # v_i is the start of l_i and the end of l_(i-1)
    ev = pr.ev & ~ee & ~ee[:, :, arrive]  # ve_k is the start of e_k and the end of e_arrive(k)
    return _Frame(V, D, Nn, pr.u, pr.s, ContactMasks(ve, ev, ee), pr.ee_lo, pr.ee_hi)


#: Slack (mm) of :func:`_masks`' test of which environment edges the object may touch:
#: far above the rounding of the placed coordinates (1e-12 mm at metres from the origin).
_NEAR_SLACK = 1e-3


def _bounding_disk(world: World) -> tuple[FloatArray, float]:
    """Centre (object frame) and radius of a disk holding the object (cached per world)."""
    hit = _DISKS.get(world)
    if hit is None:
        v = world.object.polygon.vertices
        centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
        hit = _DISKS[world] = (centre, float(np.sqrt(((v - centre) ** 2).sum(axis=1)).max()))
    return hit


_DISKS: "weakref.WeakKeyDictionary[World, tuple[FloatArray, float]]" = weakref.WeakKeyDictionary()


def _masks(world: World, poses: FloatArray, tol: float) -> ContactMasks:
    """``_frame(world, poses, tol).masks``, computed only where a contact can be.

    Every principal contact with environment edge ``j`` (or with its start vertex ``j``)
    puts an object point within ``tol`` of the segment ``e_j``, so only the (pose, edge)
    pairs whose bounding disk of the object comes within ``tol`` (plus
    :data:`_NEAR_SLACK`) of the segment are tested, by the same arithmetic on the same
    numbers as the dense frame; every other entry is False, as there. A small batch is
    computed densely (the pairs' bookkeeping costs more than it saves).
    """
    env = world.environment
    b, n, m = poses.shape[0], world.object.n, env.m
    if b < _DENSE_BELOW:
        return _frame(world, poses, tol).masks
    centre, radius = _bounding_disk(world)
    c, s_ = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    cx = c * centre[0] - s_ * centre[1] + poses[:, 0]
    cy = s_ * centre[0] + c * centre[1] + poses[:, 1]
    A, T, Le = env.vertices, env.edge_directions, env.edge_lengths
    rx, ry = cx[:, None] - A[None, :, 0], cy[:, None] - A[None, :, 1]
    along = np.clip(rx * T[None, :, 0] + ry * T[None, :, 1], 0.0, Le[None, :])
    reach = radius + tol + _NEAR_SLACK
    pb, pj = np.nonzero((rx - along * T[None, :, 0]) ** 2 + (ry - along * T[None, :, 1]) ** 2 <= reach * reach)
    ve = np.zeros((b, n, m), dtype=bool)
    ev = np.zeros((b, n, m), dtype=bool)
    ee = np.zeros((b, n, m), dtype=bool)
    if pb.size:
        V, D, Nn = _placed(world, poses)
        pr = _pair_tests(world, V[pb], D[pb], Nn[pb], pj, (pb.size, 1, 1), tol)
        prev = (np.arange(n) - 1) % n
        ee[pb, :, pj] = pr.ee[:, :, 0]
        ve[pb, :, pj] = (pr.ve & ~pr.ee & ~pr.ee[:, prev])[:, :, 0]
        arrive = env.vertex_edges[:, 0]
        ev[pb, :, pj] = pr.ev[:, :, 0] & ~pr.ee[:, :, 0] & ~ee[pb, :, arrive[pj]]
    return ContactMasks(ve, ev, ee)


#: Batches smaller than this are identified densely by :func:`_masks`.
_DENSE_BELOW = 128


def _as_poses(poses: Pose | ArrayLike) -> FloatArray:
    if isinstance(poses, Pose):
        return poses.as_array()[None, :]
    p = np.asarray(poses, dtype=float)
    return p.reshape(1, 3) if p.ndim == 1 else p


def principal_contact_masks(world: World, poses: Pose | ArrayLike, tol: float = CONTACT_TOL) -> ContactMasks:
    """Principal contacts of the object at a batch of poses, as masks.

    Parameters
    ----------
    world : World
    poses : Pose or array_like
        A :class:`Pose` or (B, 3) object poses (x, y, theta), radians.
    tol : float
        Contact tolerance (mm).

    Returns
    -------
    ContactMasks
    """
    p = _as_poses(poses)
    # Bound the (B, N, M) temporaries to a few million elements per chunk.
    chunk = max(1, 2_000_000 // max(1, world.object.n * world.environment.m))
    if p.shape[0] <= chunk:
        return _masks(world, p, float(tol))
    parts = [_masks(world, p[k:k + chunk], float(tol)) for k in range(0, p.shape[0], chunk)]
    return ContactMasks(np.concatenate([m.vertex_edge for m in parts]),
                        np.concatenate([m.edge_vertex for m in parts]),
                        np.concatenate([m.edge_edge for m in parts]))


def principal_contacts(world: World, pose: Pose, tol: float = CONTACT_TOL) -> tuple[Contact, ...]:
    """The principal contacts at ``pose``, sorted (environment feature, object feature).

    Examples
    --------
    >>> from geometry.world import Environment, Friction, Solid, TwoPointGripper, World, make_object
    >>> from geometry.shapes import make_polygon
    >>> table = Solid("table", make_polygon([[500, 0], [-500, 0], [-500, -100], [500, -100]]))
    >>> w = World(make_object([[0, 0], [70, 0], [70, 150], [0, 150]]), Environment((table,)),
    ...           TwoPointGripper(5.0, (80.0, 80.0)), Friction(0.2, 0.2))
    >>> [c.name for c in principal_contacts(w, Pose(0.0, 0.0, 0.0))]
    ['l1-e1']
    >>> [c.name for c in principal_contacts(w, Pose(0.0, 0.0, 0.3))]
    ['v1-e1']
    """
    return principal_contact_masks(world, pose, tol).contacts(0)


def contact_state(world: World, pose: Pose, tol: float = CONTACT_TOL) -> ContactState:
    """The contact state (set of principal contacts) at ``pose``; ``FREE`` when none."""
    return ContactState(principal_contacts(world, pose, tol))


# ======================================================================================
# 2. Contact geometry for mechanics
# ======================================================================================


@dataclass(frozen=True, eq=False)
class ContactPoints:
    """Point contacts between the object and the environment at one pose.

    Attributes
    ----------
    contacts : tuple of Contact
        The principal contacts (sorted as in the contact state).
    points : ndarray, (C, 2)
        World contact points (on the object).
    normals : ndarray, (C, 2)
        Unit normals pointing into the object: the direction in which the environment's
        reaction pushes it (the environment edge's outward normal for vertex-edge and
        edge-edge contacts, minus the object edge's outward normal for edge-vertex ones).
    mu : ndarray, (C,)
        Coulomb coefficient of each point (``Friction.environment_mu``).
    contact_index : ndarray of int, (C,)
        Index into ``contacts`` of the principal contact each point belongs to. An
        edge-edge contact contributes two points, the ends of its overlap segment.
    """

    contacts: tuple[Contact, ...]
    points: FloatArray
    normals: FloatArray
    mu: FloatArray
    contact_index: IntArray

    @property
    def state(self) -> ContactState:
        return ContactState(self.contacts)

    def __len__(self) -> int:
        return int(self.points.shape[0])


def contact_points(world: World, pose: Pose, tol: float = CONTACT_TOL) -> ContactPoints:
    """Identify the principal contacts at ``pose`` and return their point contacts.

    Parameters
    ----------
    world : World
    pose : Pose
        Object pose.
    tol : float
        Contact tolerance (mm).

    Returns
    -------
    ContactPoints

    Examples
    --------
    >>> from geometry.world import Environment, Friction, Solid, TwoPointGripper, World, make_object
    >>> from geometry.shapes import make_polygon
    >>> table = Solid("table", make_polygon([[500, 0], [-500, 0], [-500, -100], [500, -100]]))
    >>> w = World(make_object([[0, 0], [70, 0], [70, 150], [0, 150]]), Environment((table,)),
    ...           TwoPointGripper(5.0, (80.0, 80.0)), Friction(0.2, 0.2))
    >>> cp = contact_points(w, Pose(10.0, 0.0, 0.0))
    >>> cp.points.tolist(), cp.normals.tolist(), cp.mu.tolist()
    ([[80.0, 0.0], [10.0, 0.0]], [[0.0, 1.0], [0.0, 1.0]], [0.2, 0.2])
    """
    return _points_of(world, _frame(world, _as_poses(pose), float(tol)), 0)


def contact_point_arrays(world: World, poses: ArrayLike, tol: float = CONTACT_TOL
                         ) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.bool_]]:
    """:func:`contact_points` at each of a batch of poses as padded arrays: points and
    normals (B, C, 2), mu (B, C) and which slots are live (B, C), C the most points at
    one pose; pose b's points in the order of ``contact_points(world, poses[b])``.
    Vectorised over the batch (no object per pose)."""
    p = _as_poses(poses)
    n_obj = world.object.n
    env = world.environment
    tables = _mu_tables(world)
    chunk = max(1, 2_000_000 // max(1, n_obj * env.m))
    rows: list[tuple[FloatArray, FloatArray, FloatArray, IntArray]] = []  # per chunk: pts, nrm, mu, pose
    keys: list[IntArray] = []
    for k0 in range(0, p.shape[0], chunk):
        fr = _frame(world, p[k0:k0 + chunk], float(tol))
        m = fr.masks
        # kind ranks as ContactKind values sort: edge-edge < edge-vertex < vertex-edge
        bv, iv, jv = np.nonzero(m.vertex_edge)
        be, ie, ke = np.nonzero(m.edge_vertex)
        bb, ib, jb = np.nonzero(m.edge_edge)
        i2 = (ib + 1) % n_obj
        P, Q = fr.V[bb, ib], fr.V[bb, i2]
        uP, uQ = fr.u[bb, ib, jb], fr.u[bb, i2, jb]
        ends = []
        for ue in (fr.ee_lo[bb, ib, jb], fr.ee_hi[bb, ib, jb]):
            ends.append(P + (Q - P) * (ue - uP)[:, None] / (uQ - uP)[:, None])  # as _points_of rounds
        pts = np.concatenate([fr.V[bv, iv], env.vertices[ke], ends[0], ends[1]])
        nrm = np.concatenate([env.normals[jv], -fr.Nn[be, ie], env.normals[jb], env.normals[jb]])
        mu = np.concatenate([tables[0][iv, jv], tables[1][ie, ke], tables[2][ib, jb], tables[2][ib, jb]])
        pose = np.concatenate([bv, be, bb, bb]) + k0
        # sort key: (pose, env feature, obj feature, kind rank, end of an edge-edge overlap)
        envf = np.concatenate([jv, ke, jb, jb])
        objf = np.concatenate([iv, ie, ib, ib])
        rank = np.concatenate([np.full(bv.size, 2), np.full(be.size, 1), np.zeros(2 * bb.size, dtype=np.int64)])
        end = np.concatenate([np.zeros(bv.size + be.size, dtype=np.int64), np.zeros(bb.size, dtype=np.int64),
                              np.ones(bb.size, dtype=np.int64)])
        rows.append((pts, nrm, mu, pose))
        keys.append(np.stack([pose, envf, objf, rank, end]))
    pts = np.concatenate([r[0] for r in rows]) if rows else np.zeros((0, 2))
    nrm = np.concatenate([r[1] for r in rows]) if rows else np.zeros((0, 2))
    mu = np.concatenate([r[2] for r in rows]) if rows else np.zeros(0)
    key = np.concatenate(keys, axis=1) if keys else np.zeros((5, 0), dtype=np.int64)
    order = np.lexsort(key[::-1])
    pose = key[0, order]
    b = p.shape[0]
    counts = np.bincount(pose, minlength=b)
    c = int(counts.max(initial=0))
    slot = np.arange(order.size) - np.repeat(np.cumsum(counts) - counts, counts)
    out_p = np.zeros((b, c, 2))
    out_n = np.zeros((b, c, 2))
    out_mu = np.zeros((b, c))
    live = np.zeros((b, c), dtype=bool)
    out_p[pose, slot], out_n[pose, slot], out_mu[pose, slot], live[pose, slot] = pts[order], nrm[order], mu[order], True
    return out_p, out_n, out_mu, live


def rests_alone(world: World, poses: ArrayLike, mu_scale: float = 1.0, tol: float = CONTACT_TOL) -> BoolArray:
    """(B,) whether the object rests on the environment alone at each pose: its contacts
    there (:func:`contact_point_arrays`), all STICKING with every coefficient times
    ``mu_scale``, balance its weight (:func:`geometry.mechanics.feasible_batch`); False
    where it touches nothing."""
    from geometry import mechanics  # mechanics is the lower layer; imported where used

    p = _as_poses(poses)
    pts, nrm, mu, live = contact_point_arrays(world, p, tol)
    out = live.any(axis=1)
    if out.any():
        modes = np.where(live, mechanics.ContactMode.STICKING, mechanics.ContactMode.ABSENT).astype(np.int8)
        com = transform_points(p[out], world.object.com)[:, 0]
        c = mechanics.Contacts.make(pts[out], np.where(live[out][..., None], nrm[out], 0.0),
                                    np.where(live[out], mu[out] * mu_scale, 0.0), modes[out])
        out[out] = mechanics.feasible_batch(c, com, world.object.length_scale)
    return out


def _mu_tables(world: World) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Coefficients of every (object vertex, env edge), (object edge, env vertex) and
    (object edge, env edge) pair (:meth:`Friction.environment_mu`), cached per world."""
    hit = _MU_TABLES.get(world)
    if hit is None:
        n, m = world.object.n, world.environment.m
        fric, ve = world.friction, world.environment.vertex_edges
        hit = (np.array([[fric.environment_mu("v", i, "e", j, n_object=n) for j in range(m)] for i in range(n)]),
               np.array([[fric.environment_mu("l", i, "ve", k, world_edges=ve, n_object=n) for k in range(m)]
                         for i in range(n)]),
               np.array([[fric.environment_mu("l", i, "e", j, n_object=n) for j in range(m)] for i in range(n)]))
        _MU_TABLES[world] = hit
    return hit


_MU_TABLES: "weakref.WeakKeyDictionary[World, tuple[FloatArray, FloatArray, FloatArray]]" = weakref.WeakKeyDictionary()


def _points_of(world: World, fr: _Frame, b: int) -> ContactPoints:
    """The point contacts at pose ``b`` of a computed frame."""
    contacts = fr.masks.contacts(b)
    env = world.environment
    n_obj = world.object.n
    fric = world.friction
    pts: list[FloatArray] = []
    nrm: list[FloatArray] = []
    mus: list[float] = []
    idx: list[int] = []
    Ne = env.normals
    for c_i, c in enumerate(contacts):
        if c.kind is ContactKind.VERTEX_EDGE:
            pts.append(fr.V[b, c.obj])
            nrm.append(Ne[c.env])
            mus.append(fric.environment_mu("v", c.obj, "e", c.env, n_object=n_obj))
            idx.append(c_i)
        elif c.kind is ContactKind.EDGE_VERTEX:
            pts.append(np.array(env.vertices[c.env], dtype=float))
            nrm.append(-fr.Nn[b, c.obj])
            mus.append(fric.environment_mu("l", c.obj, "ve", c.env, world_edges=env.vertex_edges, n_object=n_obj))
            idx.append(c_i)
        else:
            i, j = c.obj, c.env
            P, Q = fr.V[b, i], fr.V[b, (i + 1) % n_obj]
            uP = float(fr.u[b, i, j])
            uQ = float(fr.u[b, (i + 1) % n_obj, j])
            mu = fric.environment_mu("l", i, "e", j, n_object=n_obj)
            for ue in (float(fr.ee_lo[b, i, j]), float(fr.ee_hi[b, i, j])):
                pts.append(P + (Q - P) * (ue - uP) / (uQ - uP))
                nrm.append(Ne[j])
                mus.append(mu)
                idx.append(c_i)
    c_count = len(pts)
    return ContactPoints(
        contacts,
        np.array(pts, dtype=float).reshape(c_count, 2),
        np.array(nrm, dtype=float).reshape(c_count, 2),
        np.array(mus, dtype=float),
        np.array(idx, dtype=np.int64),
    )


# ======================================================================================
# 3. Contact-state enumeration
# ======================================================================================


@dataclass(frozen=True)
class Workspace:
    """The part of the plane that matters for a task: an axis-aligned box.

    Only environment features on the boundary of the free space inside the box count, and
    of that free space only the connected parts containing a ``seeds`` point (all parts
    when there are no seeds): a table's underside inside the box is cut off from the task
    by the table itself and does not count.

    Attributes
    ----------
    xmin, ymin, xmax, ymax : float
        Box bounds (mm).
    seeds : tuple of (float, float)
        Free-space points selecting the connected components (e.g. points of the object at
        its start and goal poses).
    """

    xmin: float
    ymin: float
    xmax: float
    ymax: float
    seeds: tuple[tuple[float, float], ...] = ()

    @property
    def box(self) -> shapely.Polygon:
        return shapely.box(self.xmin, self.ymin, self.xmax, self.ymax)


def workspace_for_task(world: World, start: Pose, goal: Pose, margin: float | None = None) -> Workspace:
    """The workspace of a task: the bounding box of the object at ``start`` and at ``goal``
    (which holds the straight sweep between them), dilated by ``margin``.

    ``margin`` defaults to the object's diameter (largest distance between two of its
    vertices): any pose in which the object touches a feature and overlaps the swept box
    has that feature within the dilated box. Seeds are a point inside the object at
    ``start`` and at ``goal``.
    """
    v = world.object.polygon.vertices
    if margin is None:
        margin = float(np.max(np.linalg.norm(v[:, None, :] - v[None, :, :], axis=2)))
    pts = np.concatenate([world.object_vertices(start), world.object_vertices(goal)], axis=0)
    lo = pts.min(axis=0) - margin
    hi = pts.max(axis=0) + margin
    seeds = []
    for p in (start, goal):
        q = shapely.point_on_surface(shapely.Polygon(world.object_vertices(p)))
        seeds.append((float(q.x), float(q.y)))
    return Workspace(float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]), tuple(seeds))


@dataclass(frozen=True, eq=False)
class RelevantFeatures:
    """Environment features that count for a workspace.

    Attributes
    ----------
    edges : tuple of int
        Environment edges (0-based) bounding the workspace's free region.
    edge_spans : ndarray, (len(edges), 2)
        The part of each edge that does, as arc-length interval from its start vertex.
    vertices : tuple of int
        Convex environment vertices (0-based) on the boundary of the free region.
    region : shapely.Geometry
        The free region (workspace box minus the solids, selected components).
    """

    edges: tuple[int, ...]
    edge_spans: FloatArray
    vertices: tuple[int, ...]
    region: shapely.Geometry


def relevant_features(world: World, workspace: Workspace, samples: int = 64) -> RelevantFeatures:
    """Environment edges and convex vertices that bound the workspace's free region.

    An edge counts on the part of it (``samples`` cells, exact when it counts whole) whose
    free side, offset by 0.01 mm, lies in the region. A convex vertex counts when the point
    0.01 mm from it along the bisector of its edges' normals lies in the region.
    """
    env = world.environment
    solids = eroded_environment(env, 0.0).geometry
    free = shapely.difference(workspace.box, solids)
    parts = [p for p in shapely.get_parts(free) if not p.is_empty and p.area > 0]
    if workspace.seeds:
        pts = shapely.points(np.asarray(workspace.seeds, dtype=float))
        keep = [p for p in parts if bool(np.any(shapely.dwithin(p, pts, CONTACT_TOL)))]
        if not keep and parts:
            d = [float(np.min(shapely.distance(p, pts))) for p in parts]
            keep = [parts[int(np.argmin(d))]]
        parts = keep
    region = shapely.union_all(parts) if parts else shapely.Polygon()
    shapely.prepare(region)
    eps = 0.01
    edges: list[int] = []
    spans: list[tuple[float, float]] = []
    box = workspace.box
    for j in range(env.m):
        a, b = env.edges[j]
        clipped = shapely.intersection(box, shapely.LineString([a, b]))
        if clipped.is_empty or clipped.length <= EPS:
            continue
        t = env.edge_directions[j]
        cc = shapely.get_coordinates(clipped)
        proj = (cc - a) @ t
        lo, hi = float(proj.min()), float(proj.max())
        cells = (np.arange(samples) + 0.5) / samples
        uu = lo + cells * (hi - lo)
        q = a + uu[:, None] * t + eps * env.normals[j]
        inside = shapely.contains_xy(region, q[:, 0], q[:, 1])
        if not inside.any():
            continue
        k = np.flatnonzero(inside)
        edges.append(j)
        spans.append((lo + k[0] / samples * (hi - lo), lo + (k[-1] + 1) / samples * (hi - lo)))
    verts: list[int] = []
    for k in np.flatnonzero(env.vertex_convex):
        w = env.vertices[k]
        if not (workspace.xmin <= w[0] <= workspace.xmax and workspace.ymin <= w[1] <= workspace.ymax):
            continue
        n = env.normals[env.vertex_edges[k, 0]] + env.normals[env.vertex_edges[k, 1]]
        q = w + eps * n / max(np.linalg.norm(n), EPS)
        if shapely.contains_xy(region, q[0], q[1]):
            verts.append(int(k))
    return RelevantFeatures(tuple(edges), np.array(spans, dtype=float).reshape(-1, 2), tuple(verts), region)


@dataclass(frozen=True)
class StateWitness:
    """A contact state and poses that realise it (non-penetrating, identified as it)."""

    state: ContactState
    witnesses: tuple[Pose, ...]

    @property
    def name(self) -> str:
        return self.state.name


@dataclass(frozen=True, eq=False)
class _Targets:
    """Candidate principal contacts between the object and the relevant features."""

    kind: IntArray  # 0 vertex-edge, 1 edge-vertex, 2 edge-edge
    obj: IntArray
    env: IntArray
    lo: FloatArray  # relevant span on the environment edge (edge kinds)
    hi: FloatArray


_VE, _EV, _EE = 0, 1, 2


def _targets(world: World, rel: RelevantFeatures) -> _Targets:
    poly = world.object.polygon
    kind, obj, env, lo, hi = [], [], [], [], []
    for e, (a, b) in zip(rel.edges, rel.edge_spans):
        for i in np.flatnonzero(poly.convex_vertices):
            kind.append(_VE), obj.append(int(i)), env.append(e), lo.append(a), hi.append(b)
        for i in range(len(poly)):
            kind.append(_EE), obj.append(i), env.append(e), lo.append(a), hi.append(b)
    for k in rel.vertices:
        for i in range(len(poly)):
            kind.append(_EV), obj.append(i), env.append(k), lo.append(0.0), hi.append(0.0)
    return _Targets(np.array(kind, dtype=np.int64), np.array(obj, dtype=np.int64), np.array(env, dtype=np.int64),
                    np.array(lo, dtype=float), np.array(hi, dtype=float))


def _angle(v: FloatArray) -> FloatArray:
    return np.arctan2(v[..., 1], v[..., 0])


def _special_angles(world: World, rel: RelevantFeatures) -> FloatArray:
    """Orientations where a one-parameter family of poses needs an exact angle: an object
    edge antiparallel to an environment edge (edge-edge), two object vertices on one
    environment edge, two environment vertices on one object edge."""
    poly = world.object.polygon
    env = world.environment
    out: list[FloatArray] = []
    edges = np.asarray(rel.edges, dtype=np.int64)
    if edges.size:
        out.append((_angle(-env.normals[edges])[None, :] - _angle(poly.normals)[:, None]).ravel())
        v = poly.vertices
        iu, ku = np.triu_indices(len(poly), 1)
        dv = _angle(v[ku] - v[iu])
        te = _angle(env.edge_directions[edges])
        base = (te[None, :] - dv[:, None]).ravel()
        out += [base, base + math.pi]
    verts = np.asarray(rel.vertices, dtype=np.int64)
    if verts.size >= 2:
        ia, ib = np.triu_indices(verts.size, 1)
        dw = _angle(env.vertices[verts[ib]] - env.vertices[verts[ia]])
        base = (dw[None, :] - _angle(poly.edge_directions)[:, None]).ravel()
        out += [base, base + math.pi]
    if not out:
        return np.zeros(0)
    return np.concatenate(out)


def _unique_angles(a: FloatArray) -> FloatArray:
    a = np.sort(np.mod(a, 2 * math.pi))
    if a.size == 0:
        return a
    keep = np.concatenate([[True], np.diff(a) > 1e-9])
    a = a[keep]
    if a.size > 1 and a[-1] - a[0] > 2 * math.pi - 1e-9:
        a = a[:-1]
    return a


def _equations(world: World, tg: _Targets, theta: FloatArray,
               fractions: FloatArray) -> tuple[FloatArray, FloatArray, BoolArray, FloatArray]:
    """Per target c and angle t: ``a[c, t] . p = b[c, t]``, a validity mask, and the
    translations ``slide[c, t, f]`` that place the contact at fraction f of its feature."""
    poly = world.object.polygon
    env = world.environment
    C, Tn = tg.kind.size, theta.size
    cth, sth = np.cos(theta), np.sin(theta)

    def rot(v: FloatArray) -> FloatArray:  # (C, 2) body vectors -> (C, T, 2)
        return np.stack([cth[None] * v[:, None, 0] - sth[None] * v[:, None, 1],
                         sth[None] * v[:, None, 0] + cth[None] * v[:, None, 1]], axis=-1)

    is_ev = tg.kind == _EV
    e_edge = np.where(is_ev, 0, tg.env)
    n_e = env.normals[e_edge]  # (C, 2)
    t_e = env.edge_directions[e_edge]
    a_e = env.vertices[e_edge]
    vi = poly.vertices[tg.obj]  # vertex (VE) or edge start (EE, EV)
    Rv = rot(vi)  # (C, T, 2)
    # edge kinds: n_j . p = n_j . (a_j - R v_i)
    a_edge = np.broadcast_to(n_e[:, None, :], (C, Tn, 2))
    b_edge = np.einsum("ck,ctk->ct", n_e, a_e[:, None, :] - Rv)
    # edge-vertex: (R n_i) . p = (R n_i) . w_k - n_i . a_i
    n_i = poly.normals[tg.obj]
    Rn = rot(n_i)
    w = env.vertices[np.where(is_ev, tg.env, 0)]
    b_ev = np.einsum("ctk,ck->ct", Rn, w) - np.einsum("ck,ck->c", n_i, vi)[:, None]
    a = np.where(is_ev[:, None, None], Rn, a_edge)
    b = np.where(is_ev[:, None], b_ev, b_edge)
    # validity: an edge-edge target only at its antiparallel angle
    valid = np.ones((C, Tn), dtype=bool)
    is_ee = tg.kind == _EE
    if is_ee.any():
        valid[is_ee] = np.einsum("ctk,ck->ct", Rn[is_ee], n_e[is_ee]) < -1.0 + 1e-12
    # slides
    f = fractions[None, None, :, None]
    span_pt = a_e[:, None, None, :] + (tg.lo[:, None, None, None] + f * (tg.hi - tg.lo)[:, None, None, None]) \
        * t_e[:, None, None, :]  # (C, 1, F, 2)
    mid = 0.5 * (poly.vertices[tg.obj] + poly.vertices[(tg.obj + 1) % len(poly)])
    anchor = np.where((tg.kind == _VE)[:, None], vi, mid)
    slide_edge = span_pt - rot(anchor)[:, :, None, :]
    d_i = poly.edge_directions[tg.obj]
    along = vi[:, None, :] + fractions[None, :, None] * poly.edge_lengths[tg.obj][:, None, None] * d_i[:, None, :]
    Ralong = np.stack([cth[None, :, None] * along[:, None, :, 0] - sth[None, :, None] * along[:, None, :, 1],
                       sth[None, :, None] * along[:, None, :, 0] + cth[None, :, None] * along[:, None, :, 1]], axis=-1)
    slide_ev = w[:, None, None, :] - Ralong
    slide = np.where(is_ev[:, None, None, None], slide_ev, slide_edge)
    return a, b, valid, slide


def _within(world: World, tg: _Targets, c: IntArray, poses: FloatArray, tol: float) -> BoolArray:
    """Whether target contact ``c[b]`` lies within its finite features at ``poses[b]``.

    Each kind is tested on its own rows (every number is elementwise, so a row's answer
    does not depend on the others)."""
    poly = world.object.polygon
    env = world.environment
    kind = tg.kind[c]
    out = np.zeros(c.size, dtype=bool)
    for k in (_VE, _EE, _EV):
        rows = np.flatnonzero(kind == k)
        if not rows.size:
            continue
        cr, p = c[rows], poses[rows]
        oi, ej = tg.obj[cr], tg.env[cr]
        cth, sth = np.cos(p[:, 2]), np.sin(p[:, 2])

        def place(v: FloatArray) -> FloatArray:
            return np.stack([cth * v[:, 0] - sth * v[:, 1] + p[:, 0], sth * v[:, 0] + cth * v[:, 1] + p[:, 1]], -1)

        P = place(poly.vertices[oi])
        if k == _EV:
            Q = place(poly.vertices[(oi + 1) % len(poly)])
            L = poly.edge_lengths[oi]
            sv = np.einsum("bk,bk->b", env.vertices[ej] - P, (Q - P)) / L
            out[rows] = (sv >= -tol) & (sv <= L + tol)
            continue
        a_e, t_e = env.vertices[ej], env.edge_directions[ej]
        uP = np.einsum("bk,bk->b", P - a_e, t_e)
        lo, hi = tg.lo[cr], tg.hi[cr]
        if k == _VE:
            out[rows] = (uP >= lo - tol) & (uP <= hi + tol)
            continue
        Q = place(poly.vertices[(oi + 1) % len(poly)])
        uQ = np.einsum("bk,bk->b", Q - a_e, t_e)
        out[rows] = np.minimum(np.maximum(uP, uQ), hi) - np.maximum(np.minimum(uP, uQ), lo) > tol
    return out


def _farthest_points(x: FloatArray, k: int) -> IntArray:
    """Deterministic farthest-point sampling of up to ``k`` rows of ``x``."""
    n = x.shape[0]
    if n <= k:
        return np.arange(n)
    centre = x.mean(axis=0)
    first = int(np.argmin(np.linalg.norm(x - centre, axis=1)))
    chosen = [first]
    d = np.linalg.norm(x - x[first], axis=1)
    for _ in range(k - 1):
        nxt = int(np.argmax(d))
        chosen.append(nxt)
        d = np.minimum(d, np.linalg.norm(x - x[nxt], axis=1))
    return np.array(chosen, dtype=np.int64)


def row_groups(keys: IntArray) -> tuple[IntArray, IntArray]:
    """Equal rows of integer ``keys`` (N, M; signed or unsigned) grouped: each row's
    group id and each group's first row (by index), the ids numbering the distinct rows
    in lexicographic order: what ``np.unique(keys, axis=0, return_inverse=True,
    return_index=True)`` gives, by a sort of the columns (``np.unique`` sorts the rows as
    records: several times slower)."""
    n = keys.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    order = np.lexsort(keys.T[::-1])  # stable: equal rows in index order
    srt = keys[order]
    new = np.empty(n, dtype=bool)
    new[0] = True
    new[1:] = (srt[1:] != srt[:-1]).any(axis=1)
    ids = np.cumsum(new) - 1
    inv = np.empty(n, dtype=np.int64)
    inv[order] = ids
    return inv, order[new]


def _byte_words(rows: NDArray[np.uint8]) -> NDArray[np.uint64]:
    """(N, B) bytes as (N, ceil(B / 8)) unsigned integers (big-endian, zero-padded), whose
    lexicographic order is the rows' order byte by byte: :func:`row_groups` of them is
    ``np.unique(rows, axis=0)``'s grouping and numbering."""
    n, b = rows.shape
    padded = np.zeros((n, -(-b // 8) * 8), dtype=np.uint8)
    padded[:, :b] = rows
    return padded.view(">u8").astype(np.uint64)


def enumerate_contact_states(
    world: World,
    workspace: Workspace,
    *,
    angle_step_deg: float = 1.0,
    max_witnesses: int = 8,
    tol: float = CONTACT_TOL,
    penetration_tol: float = PENETRATION_TOL,
    max_contacts: int = 2,
    kinds: frozenset[ContactKind] | None = None,
) -> tuple[StateWitness, ...]:
    """Contact states with up to ``max_contacts`` principal contacts realised near the task.

    Method: for every candidate contact (object feature x relevant environment feature)
    and every pair of them, and every orientation ``theta`` on a grid (``angle_step_deg``)
    plus the exact orientations of :func:`_special_angles`, each contact is one linear
    equation ``a . p = b`` in the translation ``p`` (vertex on the line of an edge;
    environment vertex on the line of an object edge; edge-edge = antiparallel plus a
    vertex on the line). A pair is solved as a 2x2 system (a consistent rank-1 pair, like
    a single contact, is placed at several fractions along its feature). Candidates whose
    target contacts lie within their finite features, whose object does not overlap the
    solids (rule 3 at ``penetration_tol``) and whose *identified* state
    (:func:`principal_contact_masks`) has 1..``max_contacts`` principal contacts, all with relevant
    features, are collected by state. Each state keeps up to ``max_witnesses`` poses chosen
    by farthest-point sampling in (x, y, theta * object radius).

    Parameters
    ----------
    world : World
    workspace : Workspace
    angle_step_deg : float
        Orientation grid step (degrees).
    max_witnesses : int
        Witness poses kept per state.
    tol : float
        Contact tolerance (mm).
    penetration_tol : float
        Overlap tolerance of the non-penetration test (mm).
    max_contacts : int
        Largest number of principal contacts of a kept state. Poses are solved from one
        or two target contacts; a third contact present at such a pose (a notched polygon
        lying flat in a corner: its bottom edge on the wall, a vertex and an edge on the
        floor) makes a three-contact state, kept with ``max_contacts=3``.
    kinds : frozenset of ContactKind, optional
        Keep only states whose contacts are all of these kinds (default: all kinds).
        ``max_contacts=1, kinds={VERTEX_EDGE, EDGE_EDGE}`` is the reading under which the
        paper's counts (8 for task 1, 40 for task 2) are reproduced.

    Returns
    -------
    tuple of StateWitness
        Sorted by state name.
    """
    rel = relevant_features(world, workspace)
    tg = _targets(world, rel)
    if tg.kind.size == 0:
        return ()
    grid = np.deg2rad(np.arange(0.0, 360.0, angle_step_deg))
    theta = _unique_angles(np.concatenate([grid, _special_angles(world, rel)]))
    fractions = np.linspace(0.1, 0.9, 5)
    a, b, valid, slide = _equations(world, tg, theta, fractions)
    C, Tn, F = slide.shape[:3]

    cand_c: list[IntArray] = []  # target contacts (c1, c2); c2 == -1 for singles
    cand_c2: list[IntArray] = []
    cand_p: list[FloatArray] = []

    # ---- singles: each contact at each valid angle, at each fraction -----------------
    # (a 5-degree grid plus the special angles is plenty: a single contact is open in theta)
    coarse = np.isin(theta, grid[::5]) | ~np.isin(theta, grid)
    ci, ti = np.nonzero(valid & coarse[None, :])
    cand_c.append(np.repeat(ci, F))
    cand_c2.append(np.full(ci.size * F, -1))
    cand_p.append(np.concatenate([slide[ci, ti].reshape(-1, 2), np.repeat(theta[ti], F)[:, None]], axis=1))

    # ---- pairs ------------------------------------------------------------------------
    i1, i2 = np.triu_indices(C, 1)
    both = valid[i1] & valid[i2]  # (P, T)
    pi, ti = np.nonzero(both)
    c1, c2 = i1[pi], i2[pi]
    A1, A2 = a[c1, ti], a[c2, ti]
    B1, B2 = b[c1, ti], b[c2, ti]
    det = A1[:, 0] * A2[:, 1] - A1[:, 1] * A2[:, 0]
    full = np.abs(det) > 1e-9
    px = (B1[full] * A2[full, 1] - B2[full] * A1[full, 1]) / det[full]
    py = (A1[full, 0] * B2[full] - A2[full, 0] * B1[full]) / det[full]
    cand_c.append(c1[full])
    cand_c2.append(c2[full])
    cand_p.append(np.stack([px, py, theta[ti[full]]], axis=1))
    # rank 1: parallel equations; consistent ones form a family, placed along c1's feature
    r1 = ~full
    if r1.any():
        sign = np.sign(np.einsum("nk,nk->n", A1[r1], A2[r1]))
        consistent = np.abs(B1[r1] * sign - B2[r1]) <= 1e-6
        rc1, rc2, rt = c1[r1][consistent], c2[r1][consistent], ti[r1][consistent]
        if rc1.size:
            cand_c.append(np.repeat(rc1, F))
            cand_c2.append(np.repeat(rc2, F))
            cand_p.append(np.concatenate([slide[rc1, rt].reshape(-1, 2), np.repeat(theta[rt], F)[:, None]], axis=1))

    cc1 = np.concatenate(cand_c)
    cc2 = np.concatenate(cand_c2)
    poses = np.concatenate(cand_p)
    # ---- target contacts within their finite features -----------------------------------
    ok = _within(world, tg, cc1, poses, tol)
    both = np.flatnonzero(ok & (cc2 >= 0))  # the second contact, where the first holds
    ok[both] = _within(world, tg, cc2[both], poses[both], tol)
    poses = poses[ok]
    n_candidates = int(ok.size)
    # ---- cheap penetration pre-filter: no object vertex deep inside a solid ------------
    deep = eroded_environment(world.environment, max(penetration_tol, 0.5))
    if not deep.is_empty and poses.shape[0]:
        Vw = _rotate(poses[:, 2], world.object.polygon.vertices) + poses[:, None, :2]
        inside = shapely.contains_xy(deep.geometry, Vw[..., 0], Vw[..., 1]).any(axis=1)
        poses = poses[~inside]

    # ---- identify, group by state -------------------------------------------------------
    masks = principal_contact_masks(world, poses, tol)
    count = masks.counts
    env_edge_ok = np.zeros(world.environment.m, dtype=bool)
    env_edge_ok[list(rel.edges)] = True
    env_vert_ok = np.zeros(world.environment.m, dtype=bool)
    env_vert_ok[list(rel.vertices)] = True
    bad = ((masks.vertex_edge | masks.edge_edge) & ~env_edge_ok[None, None, :]).any(axis=(1, 2))
    bad |= (masks.edge_vertex & ~env_vert_ok[None, None, :]).any(axis=(1, 2))
    if kinds is not None:
        if ContactKind.VERTEX_EDGE not in kinds:
            bad |= masks.vertex_edge.any(axis=(1, 2))
        if ContactKind.EDGE_VERTEX not in kinds:
            bad |= masks.edge_vertex.any(axis=(1, 2))
        if ContactKind.EDGE_EDGE not in kinds:
            bad |= masks.edge_edge.any(axis=(1, 2))
    keep = (count >= 1) & (count <= int(max_contacts)) & ~bad
    poses = poses[keep]
    bits = np.concatenate([masks.vertex_edge[keep].reshape(poses.shape[0], -1),
                           masks.edge_vertex[keep].reshape(poses.shape[0], -1),
                           masks.edge_edge[keep].reshape(poses.shape[0], -1)], axis=1)
    if poses.shape[0] == 0:
        return ()
    inverse, heads = row_groups(_byte_words(np.packbits(bits, axis=1)))  # np.unique(axis=0)'s groups
    n_groups = heads.size
    kept_masks = ContactMasks(masks.vertex_edge[keep], masks.edge_vertex[keep], masks.edge_edge[keep])

    scale = world.object.polygon.radius
    results: list[StateWitness] = []
    budget = 512
    by_group = np.lexsort((poses[:, 2], inverse))  # group, then theta
    bounds = np.searchsorted(inverse[by_group], np.arange(n_groups + 1))
    # First an even subsample over theta of each group (one overlap test for all of
    # them), then the rest of a group in chunks until one is valid.
    orders = [by_group[bounds[g]:bounds[g + 1]] for g in range(n_groups)]
    firsts = [np.arange(0, order.size, max(1, order.size // budget)) for order in orders]
    first_sel = [order[first] for order, first in zip(orders, firsts)]
    first_free = ~object_env_overlap(world, poses[np.concatenate(first_sel)], penetration_tol) \
        if first_sel else np.zeros(0, dtype=bool)
    first_at = np.concatenate([[0], np.cumsum([sel.size for sel in first_sel])])
    for g in range(n_groups):
        order, first = orders[g], firsts[g]
        witnesses: IntArray = first_sel[g][first_free[first_at[g]:first_at[g + 1]]]
        if not witnesses.size:
            is_first = np.zeros(order.size, dtype=bool)
            is_first[first] = True
            rest = np.flatnonzero(~is_first)
            for k in range(0, rest.size, 4 * budget):
                sel = order[rest[k:k + 4 * budget]]
                witnesses = sel[~object_env_overlap(world, poses[sel], penetration_tol)]
                if witnesses.size:
                    break
        if witnesses.size == 0:
            continue
        # Distinct poses only (a zero-dimensional state has a single pose).
        _, first_of = np.unique(np.round(poses[witnesses], 6) + 0.0, axis=0, return_index=True)
        witnesses = witnesses[np.sort(first_of)]
        feats = np.column_stack([poses[witnesses, :2], poses[witnesses, 2] * scale])
        chosen = witnesses[_farthest_points(feats, max_witnesses)]
        chosen = chosen[np.lexsort((poses[chosen, 1], poses[chosen, 0], poses[chosen, 2]))]
        state = kept_masks.state(int(order[0]))
        results.append(StateWitness(state, tuple(
            Pose(float(p[0]) + 0.0, float(p[1]) + 0.0, float(wrap_angle(p[2])) + 0.0) for p in poses[chosen])))
    results.sort(key=lambda sw: sw.state.name)
    logger.debug("enumerate_contact_states: %d angles, %d candidates, %d identified poses, %d states",
                 theta.size, n_candidates, poses.shape[0], len(results))
    return tuple(results)
