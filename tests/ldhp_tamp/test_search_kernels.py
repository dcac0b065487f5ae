"""Tests of ldhp_tamp/_search.c, the grasp graph's compiled array passes: the Bellman-Ford
rounds of the optimistic passes (backward and forward), the counting order and the
selection of a layer's candidate edges from an AdjustGrasp primitive's table of pairs give
numpy's arrays bit for bit, and the search falls back to numpy where the module is not
loaded."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig

import numpy as np
import pytest

import geometry.compiled as compiled
import ldhp_tamp.grasp_graph as gg
import ldhp_tamp.kernels as kernels
import ldhp_tamp.primitives.adjust_grasp as ag

search = pytest.mark.skipif(gg._search is None,
                            reason="the compiled passes are not built, or LDHP_TAMP_PURE_NUMPY leaves them out")


def test_the_module_is_built_where_a_compiler_is() -> None:
    # optional like geometry's kernels: where the interpreter's compiler exists, a missing
    # module is a broken build
    cc = (sysconfig.get_config_var("CC") or "").split()
    if not (cc and shutil.which(cc[0])):
        pytest.skip("no C compiler: numpy computes alone")
    if os.environ.get(compiled.PURE_NUMPY_ENV, "") not in ("", "0"):
        pytest.skip(f"{compiled.PURE_NUMPY_ENV} is set: numpy computes alone")
    assert gg._search is not None and gg._search.API == kernels.SEARCH_API


@search
def test_numpy_alone_on_request() -> None:
    code = "import ldhp_tamp.grasp_graph as g; print(g._search is None)"
    for value, alone in (("1", "True"), ("0", "False")):
        env = {**os.environ, compiled.PURE_NUMPY_ENV: value}
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
        assert out.stdout.strip() == alone, out.stderr


def _numpy_order(keys: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    order = np.argsort(keys, kind="stable")
    return order, np.searchsorted(keys[order], np.arange(size + 1))


@search
@pytest.mark.parametrize("size, count", [(1, 0), (1, 5), (7, 0), (7, 40), (5000, 160_000), (70_000, 3)])
def test_the_counting_order_is_the_stable_argsort(size: int, count: int) -> None:
    rng = np.random.default_rng(size + count)
    keys = rng.integers(0, size, count)
    keys[: count // 3] = np.sort(keys[: count // 3])  # runs already in order, and repeats
    order, starts = gg._csr(keys, size)
    want_order, want_starts = _numpy_order(keys, size)
    np.testing.assert_array_equal(order, want_order)
    np.testing.assert_array_equal(starts, want_starts)
    assert order.dtype == np.int32 and starts.dtype == np.int32


@search
def test_the_counting_order_refuses_keys_out_of_range() -> None:
    with pytest.raises(ValueError, match="outside"):
        gg._search.counting_order(np.array([0, 3], dtype=np.int64), np.empty(2, dtype=np.int32),
                                  np.empty(3, dtype=np.int32))


class _Edges:  # stand-ins for a primitive's candidates: what _LayerGraph.of reads of them
    def __init__(self, src: np.ndarray, dst: np.ndarray) -> None:
        self.src, self.dst = src, dst

    def __len__(self) -> int:
        return int(self.src.size)


class _Cands:
    def __init__(self, src, dst, cost, valid) -> None:
        self.edges, self.cost, self.valid = _Edges(src, dst), cost, valid


def _random_cands(rng: np.random.Generator, size: int, edges: int) -> tuple[_Cands, ...]:
    out = []
    for _ in range(2):
        src = np.sort(rng.integers(0, size, edges // 2))
        dst = rng.integers(0, size, src.size)
        cost = np.where(rng.random(src.size) < 0.3, np.round(rng.random(src.size) * 4), rng.random(src.size) * 4)
        valid = rng.choice(np.array([-1, 0, 1], dtype=np.int8), src.size, p=[0.2, 0.6, 0.2])
        out.append(_Cands(src, dst, cost, valid))
    return tuple(out)


@search
@pytest.mark.parametrize("size, edges", [(1, 0), (6, 0), (6, 30), (300, 4000), (5000, 120_000)])
def test_the_compiled_rounds_are_numpys(size: int, edges: int, monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(size * 7 + edges)
    lg = gg._LayerGraph.of(_random_cands(rng, size, edges), size)
    members = np.ones(size, dtype=bool)
    layer = gg._Layer(0, np.zeros(3), b"", members, size, "s", lambda: members)
    for start in range(min(size, 3)):
        inter = [np.where(rng.random(size) < 0.5, rng.random(size), np.inf)]
        runs = []
        for module in (gg._search, None):
            monkeypatch.setattr(gg, "_search", module)
            opt = gg._Optimistic([layer, layer], inter, [lg, lg], start, release=False, rounds=3)
            runs.append(opt.update({0, 1}))
        (fwd_c, bwd_c), (fwd_n, bwd_n) = runs
        for got, want in ((fwd_c, fwd_n), (bwd_c, bwd_n)):
            for a, b in zip(got, want):
                assert len(a) == len(b) == 4
                for x, y in zip(a, b):
                    assert np.array_equal(x, y)  # the same values (no NaN arises)
    assert np.isfinite(bwd_c[0][-1]).any() or edges == 0 or size == 1


@search
@pytest.mark.parametrize("name", ["relax", "spread"])
def test_the_rounds_refuse_indices_outside_the_arrays(name: str) -> None:
    rounds = getattr(gg._search, name)

    def i32(*x: int) -> np.ndarray:
        return np.array(x, dtype=np.int32)

    cost, h0, out = np.ones(2), np.array([0.0, np.inf, 0.0]), np.empty((1, 3))
    good = dict(other=i32(0, 2), valid=np.zeros(2, dtype=np.int8), order=i32(0, 1), keys=i32(1), heads=i32(0))
    rounds(cost, good["other"], good["valid"], good["order"], good["keys"], good["heads"], h0, out)
    # the edges 1 -> 0 and 1 -> 2 of cost 1: backward, grasp 1 is 1 from a zero; forward,
    # grasp 1 (unreached) lowers nothing
    np.testing.assert_array_equal(out[0], [0.0, 1.0, 0.0] if name == "relax" else [0.0, np.inf, 0.0])
    for what, bad in (("other", i32(0, 3)), ("order", i32(0, 2)), ("keys", i32(3)), ("heads", i32(5))):
        args = {**good, what: bad}
        with pytest.raises(ValueError, match="outside"):
            rounds(cost, args["other"], args["valid"], args["order"], args["keys"], args["heads"], h0, out)
    with pytest.raises(ValueError, match="C-contiguous"):  # 64-bit indices are not read as 32-bit ones
        rounds(cost, good["other"].astype(np.int64), good["valid"], good["order"], good["keys"], good["heads"], h0,
               out)


@search
def test_spread_lowers_the_destinations_of_reached_sources() -> None:
    # 0 -> 1 (cost 2), 0 -> 2 (cost 5), 1 -> 2 (cost 1, known infeasible), 2 -> 0 (cost 1)
    i32 = np.int32
    cost = np.array([2.0, 5.0, 1.0, 1.0])
    other, order = np.array([1, 2, 2, 0], dtype=i32), np.array([0, 1, 2, 3], dtype=i32)
    valid = np.array([0, 1, -1, 0], dtype=np.int8)
    keys, heads = np.array([0, 1, 2], dtype=i32), np.array([0, 2, 3], dtype=i32)
    out = np.empty((2, 3))
    gg._search.spread(cost, other, valid, order, keys, heads, np.array([0.0, np.inf, np.inf]), out)
    np.testing.assert_array_equal(out, [[0.0, 2.0, 5.0], [0.0, 2.0, 5.0]])


def _random_table(rng: np.random.Generator, size: int, pairs: int) -> "ag._PairTable":
    src = rng.integers(0, size, pairs)
    dst = rng.integers(0, size, pairs)
    sense = rng.integers(-3, 4, pairs)
    parts = [(src[i::3], dst[i::3], sense[i::3], i % 2, rng.random(src[i::3].size) * 50.0) for i in range(3)]
    return ag._PairTable.of(parts + [(np.array([0]), np.array([size - 1]), 3, 1, np.array([7.5]))], size)


@search
@pytest.mark.parametrize("size, pairs", [(1, 0), (7, 40), (300, 4000), (5000, 160_000)])
def test_the_compiled_pair_selection_is_numpys(size: int, pairs: int, monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(size + pairs)
    table = _random_table(rng, size, pairs)
    monkeypatch.setattr(ag, "_search", None)
    alone = _random_table(np.random.default_rng(size + pairs), size, pairs)  # the same table, built by numpy
    monkeypatch.undo()
    for name in ("dst", "sense", "finger", "travel", "starts"):
        x, y = getattr(table, name), getattr(alone, name)
        np.testing.assert_array_equal(x, y)
        assert x.dtype == y.dtype, name
    # the table: by source, each source's pairs in the parts' order (stable)
    src = np.repeat(np.arange(size), np.diff(table.starts))
    assert table.starts[-1] == pairs + 1 and (np.diff(table.starts) >= 0).all() and table.dst.dtype == np.int32
    for share in (0.0, 0.3, 1.0):
        rows = np.flatnonzero(rng.random(size) < share)
        members = rng.random(size) < 0.6
        got = table.select(rows, members)
        monkeypatch.setattr(ag, "_search", None)
        want = table.select(rows, members)
        monkeypatch.undo()
        for x, y in zip(got, want):
            np.testing.assert_array_equal(x, y)
            assert x.dtype == y.dtype
        keep = np.isin(src, rows) & members[table.dst]
        np.testing.assert_array_equal(got[0], src[keep])
        np.testing.assert_array_equal(got[4], table.travel[keep])


@search
def test_the_pair_selection_refuses_what_it_cannot_read() -> None:
    table = ag._PairTable.of([(np.array([0, 0, 2]), np.array([1, 2, 0]), 1, 0, np.array([1.0, 2.0, 3.0]))], 3)
    sel = ag._search.select_pairs
    members = np.ones(3, dtype=np.uint8)
    assert sel(table.starts, table.dst, np.array([0, 2]), members) == 3
    out = (np.empty(2, np.int64), np.empty(2, np.int64), np.empty(2, np.int8), np.empty(2, np.int8), np.empty(2))
    with pytest.raises(ValueError, match="outputs hold 2"):  # fewer places than pairs: nothing written past them
        sel(table.starts, table.dst, np.array([0, 2]), members, table.sense, table.finger, table.travel, *out)
    for rows in (np.array([2, 0]), np.array([0, 0]), np.array([3])):
        with pytest.raises(ValueError, match="rows"):
            sel(table.starts, table.dst, rows, members)
    with pytest.raises(ValueError, match="outside"):
        sel(table.starts, np.array([1, 5, 0], dtype=np.int32), np.array([0]), members)
    with pytest.raises(ValueError, match="starts"):
        sel(np.array([0, 2, 1, 3]), table.dst, np.array([0]), members)
    with pytest.raises(ValueError, match="starts"):  # 64-bit destinations are not read as 32-bit ones
        sel(table.starts, table.dst.astype(np.int64), np.array([0]), members)
    with pytest.raises(TypeError, match="outputs"):
        sel(table.starts, table.dst, np.array([0]), members, table.sense)


@search
@pytest.mark.parametrize("size, edges", [(1, 0), (6, 30), (300, 4000), (5000, 120_000)])
def test_the_compiled_layer_order_and_selection_are_numpys(size: int, edges: int,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """A layer graph's order by source, its destinations and costs (_LayerGraph.of), and
    the edges the search checks next (_select: unchecked, near the best optimistic cost),
    compiled and with numpy; the primitives' candidates need not come sorted."""
    rng = np.random.default_rng(size * 3 + edges)
    cands = list(_random_cands(rng, size, edges))
    src = rng.integers(0, size, edges // 3)  # unsorted, as a primitive may propose them
    cands.append(_Cands(src, rng.integers(0, size, src.size), rng.random(src.size), np.zeros(src.size, np.int8)))
    cands.append(_Cands(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros(0, np.int8)))
    graphs = []
    for module in (gg._search, None):
        monkeypatch.setattr(gg, "_search", module)
        graphs.append(gg._LayerGraph.of(tuple(cands), size))
    (c, n) = graphs
    for name in ("order", "starts", "dst", "cost", "keys", "heads", "offsets"):
        x, y = getattr(c, name), getattr(n, name)
        np.testing.assert_array_equal(x, y)
        assert x.dtype == y.dtype, name
    fwd = [[np.where(rng.random(size) < 0.7, rng.random(size) * 3, np.inf)]]
    bwd = [[np.where(rng.random(size) < 0.7, rng.random(size) * 3, np.inf)]]
    picked = 0
    for best, slack in ((2.0, 1.0), (np.inf, 0.0), (0.5, 0.0)):
        picks = []
        for module in (gg._search, None):
            monkeypatch.setattr(gg, "_search", module)
            picks.append(gg._select([c], fwd, bwd, best, slack, batch=max(1, edges // 4), must=[]))
        assert picks[0].keys() == picks[1].keys()
        for key in picks[0]:
            np.testing.assert_array_equal(picks[0][key], picks[1][key])
        picked += sum(v.size for v in picks[0].values())
    assert picked or not edges


@search
def test_the_layer_order_refuses_what_it_cannot_read() -> None:
    order = gg._search.layer_order
    i64, out = np.int64, lambda n: (np.empty(n, np.int32), np.empty(4, np.int32), np.empty(n, np.int32), np.empty(n))
    good = ((np.array([2, 0], i64),), (np.array([1, 1], i64),), (np.array([1.0, 2.0]),))
    order(*good, *out(2))
    with pytest.raises(ValueError, match="outside"):
        order((np.array([3, 0], i64),), good[1], good[2], *out(2))
    with pytest.raises(ValueError, match="outside"):
        order(good[0], (np.array([1, -1], i64),), good[2], *out(2))
    with pytest.raises(ValueError, match="C-contiguous"):  # room for as many edges as given
        order(*good, *out(3))
    with pytest.raises(ValueError, match="as many"):
        order(good[0], good[1] + good[1], good[2], *out(2))


@search
def test_the_slide_table_refuses_what_it_cannot_read() -> None:
    slide = ag._search.slide_table
    i64 = lambda *x: np.array(x, dtype=np.int64)  # noqa: E731
    touching = np.array([[0, 0], [1, 0], [1, 1]], dtype=np.uint8)
    group = (i64(-1, 0, 0), i64(0, 2), i64(1, 2))  # grasps 1 and 2 slide into each other with finger 0
    none = (i64(-1, -1, -1), i64(0), i64())
    x, y = np.array([0.0, 0.0, 3.0]), np.array([0.0, 0.0, 4.0])
    starts = np.empty(4, np.int64)
    assert slide(touching, *group, *none, x, y, 10.0, starts) == 2
    np.testing.assert_array_equal(starts, [0, 0, 1, 2])
    dst, finger, travel = np.empty(2, np.int32), np.empty(2, np.int8), np.empty(2)
    slide(touching, *group, *none, x, y, 10.0, starts, dst, finger, travel)
    np.testing.assert_array_equal(dst, [2, 1])
    np.testing.assert_array_equal(travel, [5.0, 5.0])
    assert slide(touching, *group, *none, x, y, 4.9, starts) == 0  # farther than the travel allowed
    with pytest.raises(ValueError, match="room for 1"):
        slide(touching, *group, *none, x, y, 10.0, starts, dst[:1], finger[:1], travel[:1])
    with pytest.raises(ValueError, match="group outside"):
        slide(touching, i64(-1, 0, 1), group[1], group[2], *none, x, y, 10.0, starts)
    with pytest.raises(ValueError, match="member outside"):
        slide(touching, group[0], group[1], i64(1, 3), *none, x, y, 10.0, starts)
    with pytest.raises(TypeError, match="or none"):
        slide(touching, *group, *none, x, y, 10.0, starts, dst)
