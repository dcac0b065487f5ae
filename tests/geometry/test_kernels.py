"""Tests of geometry/_kernels.c, the compiled kernels (geometry.compiled): the cone test and
the fused feasibility test decide every input as numpy's rule (geometry.mechanics) does,
the convex overlap as geometry.collision's, and the dispatch falls back to numpy where it
must."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig

import numpy as np
import pytest

import geometry.collision as col
import geometry.compiled as compiled
import geometry.contacts as con
import geometry.mechanics as mech
from geometry.collision import eroded_environment, eroded_polygon
from geometry.poses import transform_points
from geometry.shapes import make_polygon
from geometry.world import Environment, Friction, Solid, TwoPointGripper, World, make_object
from geometry.mechanics import ContactMode, Contacts, cone_contains, feasible_batch, force_closure_batch

MODES = np.array([ContactMode.ABSENT, ContactMode.STICKING, ContactMode.ROLLING, ContactMode.SLIDING,
                  ContactMode.SEPARATING, ContactMode.PENETRATING], dtype=np.int8)


def _compiler_found() -> bool:
    cc = (sysconfig.get_config_var("CC") or "").split()
    return bool(cc) and shutil.which(cc[0]) is not None


kernel = pytest.mark.skipif(mech._kernels is None,
                            reason="the compiled kernels are not built, or LDHP_TAMP_PURE_NUMPY leaves them out")


def test_the_kernel_is_built_where_a_compiler_is() -> None:
    # the extension is optional (an installation without a compiler goes on with numpy);
    # where the interpreter's compiler exists, a missing kernel is a broken build
    if not _compiler_found():
        pytest.skip("no C compiler: numpy decides alone")
    if os.environ.get(compiled.PURE_NUMPY_ENV, "") not in ("", "0"):
        pytest.skip(f"{compiled.PURE_NUMPY_ENV} is set: numpy decides alone")
    assert compiled.KERNELS is not None
    assert mech._kernels is compiled.KERNELS and col._kernels is compiled.KERNELS and con._kernels is compiled.KERNELS
    assert compiled.KERNELS.MAX_SLOTS >= 16


def _contacts(rng: np.random.Generator, n: int, count: int, degenerate: bool) -> tuple[Contacts, np.ndarray, float]:
    """Random contact sets: rings around the COM, or degenerate ones (rounded points and
    normals, collinear contacts, parallel normals, contacts at the COM, mu at and around
    the frictionless threshold), all modes."""
    ang = rng.uniform(0.0, 2 * np.pi, (n, count))
    rad = rng.uniform(0.0 if degenerate else 30.0, 50.0, (n, count))
    pts = np.stack([rad * np.cos(ang), rad * np.sin(ang)], -1)
    phi = ang + np.pi + rng.uniform(-1.2, 1.2, (n, count))
    if degenerate:
        pts = np.where(rng.random((n, count, 1)) < 0.3, np.round(pts / 10.0) * 10.0, pts)
        phi = np.where(rng.random((n, count)) < 0.4, np.round(phi / (np.pi / 2)) * (np.pi / 2), phi)
        line = rng.random(n) < 0.15
        xs = rng.uniform(-50, 50, (n, count))
        pts = np.where(line[:, None, None], np.stack([xs, np.zeros_like(xs)], -1), pts)
        par = rng.random(n) < 0.15
        phi = np.where(par[:, None], np.round(rng.uniform(0, 4, (n, 1))) * np.pi / 2, phi)
        pts = np.where((rng.random((n, count)) < 0.1)[..., None], 0.0, pts)
    nrm = np.stack([np.cos(phi), np.sin(phi)], -1)
    nrm = np.where(np.abs(nrm) < 1e-12, 0.0, nrm)
    nrm /= np.hypot(nrm[..., 0], nrm[..., 1])[..., None]
    mu = np.where(rng.random((n, count)) < 0.5, rng.choice([0.0, 1e-9, 1e-8, 2e-8, 0.2, 1.0], (n, count)),
                  rng.uniform(0.0, 1.5, (n, count)))
    modes = rng.choice(MODES, (n, count), p=[0.1, 0.4, 0.15, 0.25, 0.08, 0.02])
    slide = rng.choice([-1.0, 0.0, 1.0], (n, count, 2))
    return Contacts.make(pts, nrm, mu, modes, slide), np.zeros(2), 50.0


@kernel
@pytest.mark.parametrize("count", [1, 2, 3, 4, 6, 8])
@pytest.mark.parametrize("degenerate", [False, True])
def test_the_kernel_decides_as_numpy(count: int, degenerate: bool) -> None:
    rng = np.random.default_rng(100 * count + degenerate)
    contacts, com, L = _contacts(rng, 3000, count, degenerate)
    G, _ = mech.wrench_generators(contacts, com, L)
    Gt = np.ascontiguousarray(G.transpose(2, 1, 0))
    # targets: e_y with margins, then random ones (zero components, zero targets, every
    # coordinate the largest, with either sign: the permuted cases)
    targets = [mech._shifted_target(Gt, mech._EY, eps) for eps in (0.0, 1e-7, 0.05)]
    t = rng.normal(size=(3, contacts.batch)) * (rng.random((3, contacts.batch)) < 0.7)
    t[:, :50] = 0.0
    targets.append(t)
    for target in targets:
        fast = mech._contains_compiled(Gt, target)
        rule = mech._contains_numpy(Gt, target)
        assert fast.dtype == bool
        np.testing.assert_array_equal(fast, rule)


@kernel
@pytest.mark.parametrize("batch", [1, 31, 32, 33, 8193, 20000])
def test_feasibility_is_the_same_with_and_without_the_kernel(batch: int, monkeypatch: pytest.MonkeyPatch) -> None:
    # whole calls across chunk and block boundaries, zeroed generator slots included
    rng = np.random.default_rng(batch)
    contacts, com, L = _contacts(rng, batch, 4, degenerate=True)
    margin = np.where(rng.random(batch) < 0.5, 1e-7, rng.uniform(-0.05, 0.2, batch))
    g, _ = mech.wrench_generators(contacts, com, L)
    g = np.where(rng.random(g.shape[:2] + (1,)) < 0.2, 0.0, g)
    t = rng.normal(size=(batch, 3))
    with_kernel = (feasible_batch(contacts, com, L, margin), force_closure_batch(contacts, com, L),
                   cone_contains(g, t, margin))
    monkeypatch.setattr(mech, "_kernels", None)
    without = (feasible_batch(contacts, com, L, margin), force_closure_batch(contacts, com, L),
               cone_contains(g, t, margin))
    for a, b in zip(with_kernel, without):
        np.testing.assert_array_equal(a, b)


@kernel
@pytest.mark.parametrize("count", [1, 2, 4, 8])
@pytest.mark.parametrize("per_instance", [False, True])
def test_the_fused_feasibility_decides_as_numpy(count: int, per_instance: bool) -> None:
    # generators, shifted target and cone test in one compiled call, against the numpy
    # rule: every mode, sliding directions, COM, length scale and margin per instance or
    # shared, friction coefficients overridden (as reaction_angle_batch does), and more
    # instances than a chunk
    rng = np.random.default_rng(10 * count + per_instance)
    B = mech._CHUNK + 777
    contacts, _, _ = _contacts(rng, B, count, degenerate=per_instance)
    if per_instance:
        com = np.where(rng.random((B, 1)) < 0.5, 0.0, rng.uniform(-20.0, 20.0, (B, 2)))
        inv_L = 1.0 / rng.uniform(5.0, 80.0, B)
        margin = np.where(rng.random(B) < 0.5, 1e-7, rng.uniform(-0.05, 0.2, B))
    else:
        com, inv_L, margin = np.zeros((1, 2)), np.array([1.0 / 50.0]), np.array([1e-7])
    mu = rng.uniform(0.0, 1.0, (B, count)) * (rng.random((B, count)) < 0.8)
    for override in (None, mu):
        fast = mech._feasible_impl(contacts, com, inv_L, margin, override)
        rule = mech._feasible_numpy(contacts, com, inv_L, margin, override)
        assert 0 < rule.sum() < B or count == 1
        np.testing.assert_array_equal(fast, rule)


@kernel
def test_the_kernel_is_the_version_this_module_calls() -> None:
    assert mech._kernels.API == compiled.API


@kernel
def test_numpy_alone_on_request() -> None:
    # LDHP_TAMP_PURE_NUMPY=1 leaves the kernel out (to compare the two), 0 keeps it
    code = "import geometry.mechanics as m, geometry.collision as c; print(m._kernels is None is c._kernels)"
    for value, alone in (("1", "True"), ("0", "False")):
        env = {**os.environ, "LDHP_TAMP_PURE_NUMPY": value}
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
        assert out.stdout.strip() == alone, out.stderr


@kernel
def test_more_slots_than_the_kernel_takes_go_to_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    count = mech._kernels.MAX_SLOTS // 2 + 1
    rng = np.random.default_rng(7)
    contacts, com, L = _contacts(rng, 500, count, degenerate=False)
    calls = []
    rule = mech._contains_numpy
    monkeypatch.setattr(mech, "_contains_numpy", lambda G, t: calls.append(G.shape) or rule(G, t))
    out = feasible_batch(contacts, com, L)
    assert calls and calls[0][1] == 2 * count
    monkeypatch.setattr(mech, "_kernels", None)
    np.testing.assert_array_equal(out, feasible_batch(contacts, com, L))


@kernel
def test_the_kernel_refuses_what_it_cannot_read() -> None:
    k = mech._kernels
    X = np.zeros((4, 10))
    T = np.zeros((3, 10))
    out = np.zeros(10, dtype=np.uint8)
    tol = (1e-14, 1e-12, 1e-12)
    k.contains(X, X, X, T, out, *tol)
    assert out.tolist() == [1] * 10  # zero targets are in every cone
    with pytest.raises(ValueError, match="contiguous"):
        k.contains(np.zeros((4, 20))[:, ::2], X, X, T, out, *tol)
    with pytest.raises(ValueError, match=r"\(K, b\)"):
        k.contains(X, X, X, np.zeros((3, 9)), out, *tol)
    wide = np.zeros((k.MAX_SLOTS + 1, 10))
    with pytest.raises(ValueError, match="slots"):
        k.contains(wide, wide, wide, T, out, *tol)
    with pytest.raises(TypeError):
        k.contains(X, X, X, T, b"0123456789", *tol)  # out must be writable


@kernel
def test_the_fused_kernel_refuses_what_it_cannot_read() -> None:
    k = mech._kernels
    B, C = 5, 2
    pts, mu = np.zeros((B, C, 2)), np.full((B, C), 0.5)
    modes = np.ones((B, C), dtype=np.int8)
    args = dict(com=np.zeros((1, 2)), inv_L=np.ones(1), margin=np.zeros(1))
    tail = (mech._CHUNK, mech._MODE_CODES, mech.MU_ZERO, 1e-14, 1e-12, 1e-12)

    def call(points=pts, normals=pts, mu=mu, modes=modes, slides=pts, com=args["com"], inv_L=args["inv_L"],
             margin=args["margin"], out=None):
        out = np.zeros(B, dtype=np.uint8) if out is None else out
        k.feasible(points, normals, mu, modes, slides, com, inv_L, margin, out, *tail)
        return out

    call()
    with pytest.raises(ValueError, match=r"\(B, C, 2\)"):
        call(points=np.zeros((B, C + 1, 2)))
    with pytest.raises(ValueError, match=r"\(B, C, 2\)"):
        call(com=np.zeros((B - 1, 2)))
    with pytest.raises(ValueError, match="contiguous"):
        call(mu=np.full((B, 2 * C), 0.5)[:, ::2])
    wide = k.MAX_SLOTS // 2 + 1
    with pytest.raises(ValueError, match="slots"):
        call(points=np.zeros((B, wide, 2)), normals=np.zeros((B, wide, 2)), slides=np.zeros((B, wide, 2)),
             mu=np.zeros((B, wide)), modes=np.ones((B, wide), dtype=np.int8))


# --------------------------------------------------------------------------------------
# The exact-sign overlap of convex parts (geometry.collision)
# --------------------------------------------------------------------------------------


def _slot_and_peg(tol: float):
    return eroded_environment(Environment((
        Solid("slot", make_polygon([[300, 0], [0, 0], [0, 75], [-200, 75], [-200, -50], [500, -50], [500, 75],
                                    [300, 75]])),
        Solid("peg", make_polygon([[600, 100], [610, 100], [610, 110], [600, 110]])))), tol)


@kernel
@pytest.mark.parametrize("tol", [0.0, 1e-4])
def test_the_convex_overlap_decides_as_numpy(tol: float) -> None:
    # random poses of a block and a triangle, and poses on a coarse grid that put
    # vertices exactly on the target's edges and corners (signs 0: left undecided)
    target = _slot_and_peg(tol)
    rng = np.random.default_rng(5)
    parts = [eroded_polygon(make_polygon([[0, 0], [70, 0], [70, 150], [0, 150]]), tol).parts[0],
             np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])]
    for part in parts:
        n = 4000
        poses = np.column_stack([rng.uniform(-250, 650, n), rng.uniform(-100, 150, n), rng.uniform(-4, 4, n)])
        grid = np.column_stack([rng.integers(-25, 65, n) * 10.0, rng.integers(-10, 15, n) * 10.0,
                                rng.integers(0, 4, n) * (np.pi / 2)])
        for ps in (poses, grid):
            placed = transform_points(ps, np.broadcast_to(part, (ps.shape[0],) + part.shape))
            if ps is grid:  # exact coordinates: quarter turns rounded
                placed = np.round(placed, 6)
            hit, decided = col._convex_vs_target(placed, target)
            want_hit, want_decided = col._convex_vs_target_numpy(placed, target)
            np.testing.assert_array_equal(hit, want_hit)
            np.testing.assert_array_equal(decided, want_decided)
            assert hit.any() and (~hit & decided).any()
            if ps is grid and tol == 0.0:  # vertices exactly on the target's edges
                assert (~decided).any()


@kernel
def test_the_convex_overlap_near_touching_decides_as_numpy() -> None:
    # triangles with an edge through a square's corner, shifted off it by 1e-17 .. 1e-9:
    # orientation signs at and just beyond the filter's bound
    square = eroded_polygon(make_polygon([[0, 0], [1, 0], [1, 1], [0, 1]]), 0.0)
    rng = np.random.default_rng(9)
    n = 20000
    phi = rng.uniform(0.0, 2 * np.pi, n)
    u = np.column_stack([np.cos(phi), np.sin(phi)])  # the edge's direction
    off = rng.choice([-1.0, 1.0], n) * 10.0 ** rng.uniform(-17, -9, n)
    p = 1.0 + off[:, None] * np.column_stack([-u[:, 1], u[:, 0]])  # the corner (1, 1), shifted
    s, t = rng.uniform(0.1, 3.0, (2, n))
    a, b = p - s[:, None] * u, p + t[:, None] * u
    apex = p + rng.uniform(0.5, 3.0, n)[:, None] * np.column_stack([-u[:, 1], u[:, 0]])
    placed = np.stack([a, b, apex], axis=1)  # counter-clockwise: the apex left of a -> b
    hit, decided = col._convex_vs_target(placed, square)
    want_hit, want_decided = col._convex_vs_target_numpy(placed, square)
    np.testing.assert_array_equal(hit, want_hit)
    np.testing.assert_array_equal(decided, want_decided)
    assert (~decided).sum() > 100 and decided.sum() > 100


@kernel
def test_the_convex_overlap_of_wide_polygons_goes_to_numpy(monkeypatch: pytest.MonkeyPatch) -> None:
    v = col._kernels.MAX_POLYGON + 1
    ang = np.linspace(0.0, 2 * np.pi, v, endpoint=False)
    part = np.column_stack([20 * np.cos(ang), 20 * np.sin(ang)])
    placed = transform_points(np.array([[100.0, 10.0, 0.0], [100.0, 40.0, 0.0]]), np.broadcast_to(part, (2, v, 2)))
    calls = []
    rule = col._convex_vs_target_numpy
    monkeypatch.setattr(col, "_convex_vs_target_numpy", lambda p, t: calls.append(p.shape) or rule(p, t))
    hit, decided = col._convex_vs_target(placed, _slot_and_peg(0.0))
    assert calls == [(2, v, 2)] and hit.tolist() == [True, False] and decided.all()


@kernel
def test_the_convex_overlap_refuses_what_it_cannot_read() -> None:
    k = col._kernels
    edges = np.zeros((3, 2))
    hit, decided = np.zeros(2, dtype=np.uint8), np.zeros(2, dtype=np.uint8)
    poly = np.zeros((2, 4, 2))
    k.convex_overlap(poly, 4, edges, edges, edges, edges, hit, decided, 1e-15, 1e-250)
    with pytest.raises(ValueError, match=r"\(B, V, 2\)"):
        k.convex_overlap(poly, 5, edges, edges, edges, edges, hit, decided, 1e-15, 1e-250)
    with pytest.raises(ValueError, match=r"\(K, 2\)"):
        k.convex_overlap(poly, 4, edges, np.zeros((2, 2)), edges, edges, hit, decided, 1e-15, 1e-250)
    with pytest.raises(ValueError, match="contiguous"):
        k.convex_overlap(np.zeros((2, 8, 2))[:, ::2], 4, edges, edges, edges, edges, hit, decided, 1e-15, 1e-250)


# --------------------------------------------------------------------------------------
# The principal-contact tests (geometry.contacts)
# --------------------------------------------------------------------------------------


def _slot_world(obj) -> World:
    slot = make_polygon([[-200, 75], [-200, -50], [500, -50], [500, 75], [300, 75], [300, 0], [0, 0], [0, 75]])
    peg = make_polygon([[600, 100], [610, 100], [605, 110]])
    return World(make_object(obj), Environment((Solid("slot", slot), Solid("peg", peg))),
                 TwoPointGripper(5.0, (80.0, 80.0)), Friction(0.2, 0.2))


@kernel
@pytest.mark.parametrize("obj", [[[0, 0], [70, 0], [70, 150], [0, 150]],
                                 [[0, 0], [40, 0], [40, 10], [10, 10], [10, 30], [0, 30]]])
@pytest.mark.parametrize("tol", [0.0, 0.1])
def test_the_pair_tests_are_numpy_s(obj, tol: float) -> None:
    # dense frames and chosen (pose, edge) pairs; random poses and poses resting exactly
    # on the slot's faces, walls and corners, at quarter turns (contacts at the tolerance)
    world = _slot_world(obj)
    rng = np.random.default_rng(3)
    n = 600
    free = np.column_stack([rng.uniform(-250, 650, n), rng.uniform(-60, 160, n), rng.uniform(-np.pi, np.pi, n)])
    rest = np.column_stack([rng.choice([0.0, 230.0, 300.0, -40.0, 600.0], n) + rng.choice([0.0, tol, -tol, 1e-9], n),
                            rng.choice([0.0, 75.0, 110.0, -50.0], n) + rng.choice([0.0, tol, -tol], n),
                            rng.integers(0, 4, n) * (np.pi / 2)])
    env = world.environment
    for poses in (free, rest):
        V, D, Nn = con._placed(world, poses)
        pairs = [(slice(None), (1, 1, env.m), V, D, Nn)]
        pb = rng.integers(0, n, 900)
        pj = rng.integers(0, env.m, 900)
        pairs.append((pj, (pb.size, 1, 1), V[pb], D[pb], Nn[pb]))
        for j, shape, v, d, nn in pairs:
            got = con._pair_tests(world, v, d, nn, j, shape, tol)
            want = con._pair_tests_numpy(world, v, d, nn, j, shape, tol)
            for field in ("u", "s", "ve", "ev", "ee", "ee_lo", "ee_hi"):
                np.testing.assert_array_equal(getattr(got, field), getattr(want, field), err_msg=field)
            if poses is rest:
                assert want.ve.any() and want.ee.any()


@kernel
def test_the_pair_tests_refuse_what_they_cannot_read() -> None:
    k = con._kernels
    X, N, Y = 2, 3, 4
    obj = np.zeros((X, N, 2))
    tables = np.zeros((10, 1, Y))
    out = [np.zeros((X, N, Y)) for _ in range(4)] + [np.zeros((X, N, Y), dtype=np.uint8) for _ in range(3)]
    k.pair_tests(obj, obj, obj, X, N, Y, tables, np.zeros((1, Y), np.uint8), 1, np.ones(N), np.ones(N, np.uint8),
                 0.1, 1e-12, *out)
    with pytest.raises(ValueError, match="Xe 1 or X"):
        k.pair_tests(obj, obj, obj, X, N, Y, np.zeros((10, 3, Y)), np.zeros((3, Y), np.uint8), 3, np.ones(N),
                     np.ones(N, np.uint8), 0.1, 1e-12, *out)
    with pytest.raises(ValueError, match="contiguous"):
        k.pair_tests(np.zeros((X, 2 * N, 2))[:, ::2], obj, obj, X, N, Y, tables, np.zeros((1, Y), np.uint8), 1,
                     np.ones(N), np.ones(N, np.uint8), 0.1, 1e-12, *out)
