/*
 * ldhp_tamp._search: compiled twins of the grasp graph's array passes that numpy makes as
 * several passes over a layer's candidate edges (hundreds of thousands of them), each
 * giving numpy's result bit for bit (the same additions, and minima, which are exact);
 * tests pin each to its numpy form (tests/ldhp_tamp/test_search_kernels.py).
 * ldhp_tamp.grasp_graph loads the module (or not: numpy computes alone).
 *
 * A layer's edges are kept in one order, by source (grasp_graph._LayerGraph): group i is
 * the edges heads[i] .. heads[i + 1] - 1 (or to the end) of the source keys[i]; other[j]
 * is edge j's destination, cost[j] its cost, order[j] its index among the layer's
 * candidates (where valid[] says whether it is known infeasible, < 0).
 *
 *  - relax(cost, other, valid, order, keys, heads, h0, out): the backward Bellman-Ford
 *    rounds of the optimistic cost passes (grasp_graph._Optimistic), each
 *        best[keys[i]] = min over the group's edges j with valid[order[j]] >= 0 of
 *                        cost[j] + prev[other[j]]
 *        out[r] = minimum(prev, best)          (best is +inf where no edge counts)
 *    with prev = h0 for the first round and out[r - 1] after it. numpy's form is
 *    minimum.reduceat over cost (set to +inf where the edge is known infeasible) plus
 *    prev gathered at other; an edge whose prev is +inf adds nothing, so it is skipped.
 *  - spread(cost, other, valid, order, keys, heads, h0, out): the forward rounds over the
 *    same groups, each edge's cost[j] + prev[keys[i]] lowering out[r][other[j]] (numpy's
 *    form groups the edges by destination; the minimum is the same, as is each sum).
 *    After the first round only the sources the round before lowered push: the others'
 *    sums are the round before's, which prev holds already (task 1: 38 % fewer edges).
 *  - counting_order(keys, order, starts): the stable order of keys in [0, size) (numpy's
 *    argsort(kind="stable")) and, in starts (size + 1), where each key's run begins in
 *    it (searchsorted of the sorted keys), by one counting pass.
 *  - layer_order(srcs, dsts, costs, order, starts, dst, cost): a layer's candidate edges,
 *    given as each primitive's (src, dst, cost) (tuples of int64, int64 and double
 *    buffers), in one order by source: counting_order of their sources concatenated, and
 *    the destinations (as int32) and costs taken in that order (grasp_graph._LayerGraph.of;
 *    numpy concatenates the primitives' arrays and takes them in the order).
 *  - near_best(valid, order, keys, heads, dst, cost, fwd, bwd, bound, out, f): the
 *    positions of a layer's edges not yet checked (valid[order[j]] == 0) whose cheapest
 *    optimistic path through them, (fwd[source] + cost[j]) + bwd[dst[j]], is at most
 *    bound, ascending, into out (int32), and those costs into f (room for every edge in
 *    both); returns how many (grasp_graph._select; numpy's form computes the cost of
 *    every edge).
 *  - slide_table(touching, of0, start0, members0, of1, start1, members1, x, y, max_travel,
 *    starts[, dst, finger, travel]): the table of every slide of a grasp set
 *    (adjust_grasp.Slide._table) straight from the slide groups: for each source g in
 *    turn, finger 0's slides if g touches with finger 0, then finger 1's if g touches
 *    with finger 1 alone; the members of g's group of that finger (of, start, members:
 *    adjust_grasp._Groups, int64) in group order, but g itself and those farther than
 *    max_travel (hypot of the grippers' x and y differences, as numpy's norm rounds it).
 *    Fills starts (int64, G + 1) and returns how many slides; given dst (int32), finger
 *    (int8) and travel (double) for that many, fills them too. touching is (G, 2) bytes.
 *  - select_pairs(starts, dst, rows, members[, sense, finger, travel, out_src, out_dst,
 *    out_sense, out_finger, out_travel]): a layer's candidate edges from a table of every
 *    pair of the grasp set by source (adjust_grasp._PairTable: source g's pairs are
 *    starts[g] .. starts[g + 1] - 1, int64; dst int32, sense and finger int8, travel
 *    double): the pairs of the sources rows (int64, strictly ascending) whose destination
 *    is in members (a byte per grasp), in the table's order. Returns how many; given the
 *    out buffers (as many items each: src and dst int64) it copies them out too. numpy's
 *    form masks the whole table (sources in rows and destinations in members).
 *
 * Buffers are C-contiguous: doubles, int32 (the indices: a layer's edges and grasps are
 * far fewer than 2^31), int8, and int64 where said (counting_order's keys, select_pairs'
 * starts, rows and outputs). The GIL is released while computing.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

/* the interface ldhp_tamp.grasp_graph expects (its SEARCH_API) */
#define API_VERSION 5

/* whether the indices of a relax() or spread() call lie where the arrays are (they come
   from grasp_graph._LayerGraph.of; a bad one is a ValueError, not a stray read) */
static int
indices_ok(const int32_t *other, const int32_t *order, const int32_t *keys, const int32_t *heads,
           Py_ssize_t m, Py_ssize_t E, Py_ssize_t size)
{
    for (Py_ssize_t j = 0; j < E; j++)
        if (other[j] < 0 || other[j] >= size || order[j] < 0 || order[j] >= E)
            return 0;
    for (Py_ssize_t i = 0; i < m; i++)
        if (keys[i] < 0 || keys[i] >= size || heads[i] < 0 || heads[i] > E || (i > 0 && heads[i] < heads[i - 1]))
            return 0;
    return 1;
}

/* Bellman-Ford rounds over the source groups: backward (relax) each source takes its
   cheapest edge's cost plus the other end's; forward (spread) each reached source lowers
   its edges' other ends. A branch per group, not per edge. */
static void
rounds_of(const double *cost, const int32_t *other, const int8_t *valid, const int32_t *order, const int32_t *keys,
          const int32_t *heads, Py_ssize_t m, Py_ssize_t E, const double *h0, double *out, Py_ssize_t size,
          Py_ssize_t rounds, int forward)
{
    const double *prev = h0, *before = NULL;
    for (Py_ssize_t r = 0; r < rounds; r++) {
        double *cur = out + r * size;
        memcpy(cur, prev, (size_t)size * sizeof(double));
        for (Py_ssize_t i = 0; i < m; i++) {
            Py_ssize_t lo = (Py_ssize_t)heads[i], hi = i + 1 < m ? (Py_ssize_t)heads[i + 1] : E;
            int32_t k = keys[i];
            if (forward) {
                double h = prev[k];
                /* a source the last round did not lower lowers nothing now: its sums are
                   those of the last round, which prev holds already */
                if (h == INFINITY || (before != NULL && h == before[k]))
                    continue;
                for (Py_ssize_t j = lo; j < hi; j++) {
                    if (valid[order[j]] < 0)
                        continue;
                    double v = cost[j] + h;
                    int32_t d = other[j];
                    if (v < cur[d])
                        cur[d] = v;
                }
            } else {
                double best = INFINITY;
                for (Py_ssize_t j = lo; j < hi; j++) {
                    double h = prev[other[j]];
                    if (h == INFINITY || valid[order[j]] < 0)
                        continue;
                    double v = cost[j] + h;
                    if (v < best)
                        best = v;
                }
                if (best < cur[k])
                    cur[k] = best;
            }
        }
        before = prev;
        prev = cur;
    }
}

static void
counting_order(const int64_t *keys, Py_ssize_t E, Py_ssize_t size, int32_t *order, int32_t *starts)
{
    memset(starts, 0, (size_t)(size + 1) * sizeof(int32_t));
    for (Py_ssize_t j = 0; j < E; j++)
        starts[keys[j] + 1]++;
    for (Py_ssize_t i = 0; i < size; i++)
        starts[i + 1] += starts[i];
    /* place each key after the earlier ones of its run (starts[k] walks to the next run's
       start), then shift the starts back by one run */
    for (Py_ssize_t j = 0; j < E; j++)
        order[starts[keys[j]]++] = (int32_t)j;
    for (Py_ssize_t i = size; i > 0; i--)
        starts[i] = starts[i - 1];
    starts[0] = 0;
}

static int
check(Py_buffer *b, Py_ssize_t itemsize, Py_ssize_t count, const char *name, const char *what)
{
    if (!PyBuffer_IsContiguous(b, 'C') || b->len != itemsize * count) {
        PyErr_Format(PyExc_ValueError, "%s: %s: a C-contiguous buffer of %zd items of %zd bytes expected", name,
                     what, count, itemsize);
        return 0;
    }
    return 1;
}

/* the buffers a call got released (a buffer it did not get has no object: nothing to do) */
static void
release(Py_buffer **all, size_t n)
{
    for (size_t q = 0; q < n; q++)
        PyBuffer_Release(all[q]);
}

/* relax() and spread() take the same arguments */
static PyObject *
rounds_py(PyObject *args, const char *name, int forward)
{
    Py_buffer cost, other, valid, order, keys, heads, h0, out;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*y*w*", &cost, &other, &valid, &order, &keys, &heads, &h0, &out))
        return NULL;
    PyObject *result = NULL;
    Py_buffer *all[] = {&cost, &other, &valid, &order, &keys, &heads, &h0, &out};
    Py_ssize_t D = (Py_ssize_t)sizeof(double), I = (Py_ssize_t)sizeof(int32_t);
    Py_ssize_t E = cost.len / D, m = keys.len / I, size = h0.len / D, V = valid.len;
    Py_ssize_t rounds = size ? out.len / D / size : 0;
    if (!check(&cost, D, E, name, "cost") || !check(&other, I, E, name, "other")
        || !check(&valid, 1, V, name, "valid") || !check(&order, I, E, name, "order")
        || !check(&keys, I, m, name, "keys") || !check(&heads, I, m, name, "heads")
        || !check(&h0, D, size, name, "h0") || !check(&out, D, rounds * size, name, "out"))
        goto done;
    if (V != E) {
        PyErr_Format(PyExc_ValueError, "%s: valid must have one entry per edge", name);
        goto done;
    }
    int ok;
    Py_BEGIN_ALLOW_THREADS
    ok = indices_ok(other.buf, order.buf, keys.buf, heads.buf, m, E, size);
    if (ok)
        rounds_of(cost.buf, other.buf, valid.buf, order.buf, keys.buf, heads.buf, m, E, h0.buf, out.buf, size, rounds,
                  forward);
    Py_END_ALLOW_THREADS
    if (!ok) {
        PyErr_Format(PyExc_ValueError, "%s: an index outside its array (other, order, keys or heads)", name);
        goto done;
    }
    result = Py_NewRef(Py_None);
done:
    release(all, sizeof(all) / sizeof(all[0]));
    return result;
}

static PyObject *
relax_py(PyObject *Py_UNUSED(self), PyObject *args)
{
    return rounds_py(args, "relax", 0);
}

static PyObject *
spread_py(PyObject *Py_UNUSED(self), PyObject *args)
{
    return rounds_py(args, "spread", 1);
}

static PyObject *
counting_order_py(PyObject *Py_UNUSED(self), PyObject *args)
{
    Py_buffer keys, order, starts;
    if (!PyArg_ParseTuple(args, "y*w*w*", &keys, &order, &starts))
        return NULL;
    PyObject *result = NULL;
    Py_buffer *all[] = {&keys, &order, &starts};
    Py_ssize_t K = (Py_ssize_t)sizeof(int64_t), I = (Py_ssize_t)sizeof(int32_t);
    Py_ssize_t E = keys.len / K, size = starts.len / I - 1;
    if (!check(&keys, K, E, "counting_order", "keys") || !check(&order, I, E, "counting_order", "order")
        || size < 0 || !check(&starts, I, size + 1, "counting_order", "starts"))
        goto done;
    if (E > INT32_MAX) {
        PyErr_SetString(PyExc_ValueError, "counting_order: more than 2^31 - 1 keys");
        goto done;
    }
    const int64_t *k = keys.buf;
    for (Py_ssize_t j = 0; j < E; j++) {
        if (k[j] < 0 || k[j] >= size) {
            PyErr_Format(PyExc_ValueError, "counting_order: key %lld outside [0, %zd)", (long long)k[j], size);
            goto done;
        }
    }
    Py_BEGIN_ALLOW_THREADS
    counting_order(k, E, size, order.buf, starts.buf);
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    release(all, sizeof(all) / sizeof(all[0]));
    return result;
}

/* select_pairs(): count the pairs (o_src == NULL) or copy them out too, at most cap of
   them (*count then says how many there are, cap + 1 once past it); 0, or a bad index's
   position + 1 (dst outside [0, size)) */
static Py_ssize_t
select_of(const int64_t *starts, const int32_t *dst, const int64_t *rows, Py_ssize_t R, const uint8_t *members,
          Py_ssize_t size, const int8_t *sense, const int8_t *finger, const double *travel, int64_t *o_src,
          int64_t *o_dst, int8_t *o_sense, int8_t *o_finger, double *o_travel, Py_ssize_t cap, Py_ssize_t *count)
{
    Py_ssize_t n = 0;
    for (Py_ssize_t i = 0; i < R; i++) {
        int64_t g = rows[i];
        for (int64_t j = starts[g]; j < starts[g + 1]; j++) {
            int64_t d = dst[j];
            if (d < 0 || d >= size)
                return (Py_ssize_t)j + 1;
            if (!members[d])
                continue;
            if (o_src != NULL) {
                if (n == cap) {
                    *count = cap + 1;
                    return 0;
                }
                o_src[n] = g;
                o_dst[n] = d;
                o_sense[n] = sense[j];
                o_finger[n] = finger[j];
                o_travel[n] = travel[j];
            }
            n++;
        }
    }
    *count = n;
    return 0;
}

static PyObject *
select_pairs_py(PyObject *Py_UNUSED(self), PyObject *args)
{
    Py_buffer starts, dst, rows, members, b[8];
    memset(b, 0, sizeof(b));
    if (!PyArg_ParseTuple(args, "y*y*y*y*|y*y*y*w*w*w*w*w*", &starts, &dst, &rows, &members, &b[0], &b[1], &b[2],
                          &b[3], &b[4], &b[5], &b[6], &b[7]))
        return NULL;
    PyObject *result = NULL;
    Py_buffer *all[] = {&starts, &dst, &rows, &members, &b[0], &b[1], &b[2], &b[3], &b[4], &b[5], &b[6], &b[7]};
    int copy = b[0].obj != NULL;
    const char *name = "select_pairs";
    Py_ssize_t L = (Py_ssize_t)sizeof(int64_t), I = (Py_ssize_t)sizeof(int32_t), D = (Py_ssize_t)sizeof(double);
    Py_ssize_t size = members.len, E = dst.len / I, R = rows.len / L, cap = 0;
    if (!check(&starts, L, size + 1, name, "starts") || !check(&dst, I, E, name, "dst")
        || !check(&rows, L, R, name, "rows") || !check(&members, 1, size, name, "members"))
        goto done;
    if (copy) {
        if (b[7].obj == NULL) {
            PyErr_SetString(PyExc_TypeError, "select_pairs: the payload (sense, finger, travel) and all five outputs, "
                                             "or none of them");
            goto done;
        }
        cap = b[3].len / L;
        if (!check(&b[0], 1, E, name, "sense") || !check(&b[1], 1, E, name, "finger")
            || !check(&b[2], D, E, name, "travel") || !check(&b[3], L, cap, name, "out_src")
            || !check(&b[4], L, cap, name, "out_dst") || !check(&b[5], 1, cap, name, "out_sense")
            || !check(&b[6], 1, cap, name, "out_finger") || !check(&b[7], D, cap, name, "out_travel"))
            goto done;
    }
    const int64_t *st = starts.buf, *rw = rows.buf;
    for (Py_ssize_t i = 0; i <= size; i++) {
        if (st[i] < 0 || st[i] > E || (i > 0 && st[i] < st[i - 1]) || (i == 0 && st[i] != 0)
            || (i == size && st[i] != E)) {
            PyErr_Format(PyExc_ValueError, "%s: starts must rise from 0 to the %zd pairs of dst", name, E);
            goto done;
        }
    }
    for (Py_ssize_t i = 0; i < R; i++) {
        if (rw[i] < 0 || rw[i] >= size || (i > 0 && rw[i] <= rw[i - 1])) {
            PyErr_Format(PyExc_ValueError, "%s: rows must rise strictly within [0, %zd)", name, size);
            goto done;
        }
    }
    Py_ssize_t n = 0, bad;
    Py_BEGIN_ALLOW_THREADS
    bad = select_of(st, dst.buf, rw, R, members.buf, size, copy ? b[0].buf : NULL, copy ? b[1].buf : NULL,
                    copy ? b[2].buf : NULL, copy ? b[3].buf : NULL, copy ? b[4].buf : NULL, copy ? b[5].buf : NULL,
                    copy ? b[6].buf : NULL, copy ? b[7].buf : NULL, cap, &n);
    Py_END_ALLOW_THREADS
    if (bad) {
        PyErr_Format(PyExc_ValueError, "%s: dst[%zd] outside [0, %zd)", name, bad - 1, size);
        goto done;
    }
    if (copy && n != cap) {
        PyErr_Format(PyExc_ValueError, "%s: the outputs hold %zd pairs, %s", name, cap,
                     n > cap ? "more are selected" : "fewer are selected");
        goto done;
    }
    result = PyLong_FromSsize_t(n);
done:
    release(all, sizeof(all) / sizeof(all[0]));
    return result;
}

/* layer_order(): the parts' sources counted into starts, then each edge placed after
   the earlier ones of its source (parts in order, each in its order: stable) */
static PyObject *
layer_order_py(PyObject *Py_UNUSED(self), PyObject *args)
{
    PyObject *srcs, *dsts, *costs;
    Py_buffer order, starts, dst, cost;
    if (!PyArg_ParseTuple(args, "O!O!O!w*w*w*w*", &PyTuple_Type, &srcs, &PyTuple_Type, &dsts, &PyTuple_Type, &costs,
                          &order, &starts, &dst, &cost))
        return NULL;
    const char *name = "layer_order";
    PyObject *result = NULL;
    Py_ssize_t P = PyTuple_GET_SIZE(srcs), got = 0;
    Py_buffer *parts = PyMem_Calloc((size_t)(3 * P + 1), sizeof(Py_buffer));
    int32_t *walk = NULL;
    Py_ssize_t L = (Py_ssize_t)sizeof(int64_t), I = (Py_ssize_t)sizeof(int32_t), D = (Py_ssize_t)sizeof(double);
    Py_ssize_t size = starts.len / I - 1, total = 0;
    if (parts == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    if (PyTuple_GET_SIZE(dsts) != P || PyTuple_GET_SIZE(costs) != P) {
        PyErr_Format(PyExc_ValueError, "%s: as many destinations and costs as sources", name);
        goto done;
    }
    for (Py_ssize_t p = 0; p < P; p++) {
        PyObject *three[3] = {PyTuple_GET_ITEM(srcs, p), PyTuple_GET_ITEM(dsts, p), PyTuple_GET_ITEM(costs, p)};
        for (int q = 0; q < 3; q++) {
            if (PyObject_GetBuffer(three[q], &parts[3 * p + q], PyBUF_C_CONTIGUOUS) < 0)
                goto done;
            got = 3 * p + q + 1;
        }
        Py_ssize_t n = parts[3 * p].len / L;
        if (!check(&parts[3 * p], L, n, name, "src") || !check(&parts[3 * p + 1], L, n, name, "dst")
            || !check(&parts[3 * p + 2], D, n, name, "cost"))
            goto done;
        total += n;
    }
    if (size < 0 || !check(&order, I, total, name, "order") || !check(&starts, I, size + 1, name, "starts")
        || !check(&dst, I, total, name, "dst out") || !check(&cost, D, total, name, "cost out"))
        goto done;
    if (total > INT32_MAX) {
        PyErr_Format(PyExc_ValueError, "%s: more than 2^31 - 1 edges", name);
        goto done;
    }
    for (Py_ssize_t p = 0; p < P; p++) {
        const int64_t *sp = parts[3 * p].buf, *dp = parts[3 * p + 1].buf;
        for (Py_ssize_t j = 0, n = parts[3 * p].len / L; j < n; j++) {
            if (sp[j] < 0 || sp[j] >= size || dp[j] < 0 || dp[j] >= size) {
                PyErr_Format(PyExc_ValueError, "%s: an edge of part %zd outside [0, %zd)", name, p, size);
                goto done;
            }
        }
    }
    walk = PyMem_Malloc((size_t)(size + 1) * sizeof(int32_t));
    if (walk == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    Py_BEGIN_ALLOW_THREADS
    int32_t *st = starts.buf, *ord = order.buf, *dout = dst.buf;
    double *cout = cost.buf;
    memset(st, 0, (size_t)(size + 1) * sizeof(int32_t));
    for (Py_ssize_t p = 0; p < P; p++) {
        const int64_t *sp = parts[3 * p].buf;
        for (Py_ssize_t j = 0, n = parts[3 * p].len / L; j < n; j++)
            st[sp[j] + 1]++;
    }
    for (Py_ssize_t i = 0; i < size; i++)
        st[i + 1] += st[i];
    memcpy(walk, st, (size_t)(size + 1) * sizeof(int32_t));
    Py_ssize_t base = 0;
    for (Py_ssize_t p = 0; p < P; p++) {
        const int64_t *sp = parts[3 * p].buf, *dp = parts[3 * p + 1].buf;
        const double *cp = parts[3 * p + 2].buf;
        Py_ssize_t n = parts[3 * p].len / L;
        for (Py_ssize_t j = 0; j < n; j++) {
            int32_t at = walk[sp[j]]++;
            ord[at] = (int32_t)(base + j);
            dout[at] = (int32_t)dp[j];
            cout[at] = cp[j];
        }
        base += n;
    }
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    PyMem_Free(walk);
    if (parts != NULL) {
        for (Py_ssize_t q = 0; q < got; q++)
            PyBuffer_Release(&parts[q]);
        PyMem_Free(parts);
    }
    PyBuffer_Release(&order);
    PyBuffer_Release(&starts);
    PyBuffer_Release(&dst);
    PyBuffer_Release(&cost);
    return result;
}

/* near_best(): one pass over the source groups */
static PyObject *
near_best_py(PyObject *Py_UNUSED(self), PyObject *args)
{
    Py_buffer valid, order, keys, heads, dst, cost, fwd, bwd, out, fout;
    double bound;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*y*y*dw*w*", &valid, &order, &keys, &heads, &dst, &cost, &fwd, &bwd,
                          &bound, &out, &fout))
        return NULL;
    const char *name = "near_best";
    PyObject *result = NULL;
    Py_buffer *all[] = {&valid, &order, &keys, &heads, &dst, &cost, &fwd, &bwd, &out, &fout};
    Py_ssize_t D = (Py_ssize_t)sizeof(double), I = (Py_ssize_t)sizeof(int32_t);
    Py_ssize_t E = cost.len / D, m = keys.len / I, size = fwd.len / D, V = valid.len;
    if (!check(&valid, 1, V, name, "valid") || !check(&order, I, E, name, "order") || !check(&keys, I, m, name, "keys")
        || !check(&heads, I, m, name, "heads") || !check(&dst, I, E, name, "dst") || !check(&cost, D, E, name, "cost")
        || !check(&fwd, D, size, name, "fwd") || !check(&bwd, D, size, name, "bwd") || !check(&out, I, E, name, "out")
        || !check(&fout, D, E, name, "f"))
        goto done;
    if (V != E) {
        PyErr_Format(PyExc_ValueError, "%s: valid must have one entry per edge", name);
        goto done;
    }
    int ok;
    Py_ssize_t n = 0;
    Py_BEGIN_ALLOW_THREADS
    ok = indices_ok(dst.buf, order.buf, keys.buf, heads.buf, m, E, size);
    if (ok) {
        const int8_t *va = valid.buf;
        const int32_t *ord = order.buf, *ks = keys.buf, *hs = heads.buf, *ds = dst.buf;
        const double *c = cost.buf, *fw = fwd.buf, *bw = bwd.buf;
        int32_t *o = out.buf;
        double *fo = fout.buf;
        for (Py_ssize_t i = 0; i < m; i++) {
            Py_ssize_t lo = (Py_ssize_t)hs[i], hi = i + 1 < m ? (Py_ssize_t)hs[i + 1] : E;
            double h = fw[ks[i]];
            for (Py_ssize_t j = lo; j < hi; j++) {
                if (va[ord[j]] != 0)
                    continue;
                double f = (h + c[j]) + bw[ds[j]];
                if (f <= bound) {
                    o[n] = (int32_t)j;
                    fo[n++] = f;
                }
            }
        }
    }
    Py_END_ALLOW_THREADS
    if (!ok) {
        PyErr_Format(PyExc_ValueError, "%s: an index outside its array (dst, order, keys or heads)", name);
        goto done;
    }
    result = PyLong_FromSsize_t(n);
done:
    release(all, sizeof(all) / sizeof(all[0]));
    return result;
}

/* slide_table(): one pass (count, or fill) over the sources and their groups */
static Py_ssize_t
slides_of(const uint8_t *touching, const int64_t *of[2], const int64_t *start[2], const int64_t *members[2],
          const double *x, const double *y, double max_travel, Py_ssize_t size, int64_t *starts, int32_t *dst,
          int8_t *finger, double *travel)
{
    Py_ssize_t n = 0;
    for (Py_ssize_t g = 0; g < size; g++) {
        starts[g] = n;
        for (int k = 0; k < 2; k++) {
            if (!touching[2 * g + k] || (k == 1 && touching[2 * g]) || of[k][g] < 0)
                continue;
            int64_t grp = of[k][g];
            for (int64_t i = start[k][grp]; i < start[k][grp + 1]; i++) {
                int64_t m = members[k][i];
                if (m == g)
                    continue;
                double dx = x[m] - x[g], dy = y[m] - y[g];
                double t = sqrt(dx * dx + dy * dy);
                if (!(t <= max_travel))
                    continue;
                if (dst != NULL) {
                    dst[n] = (int32_t)m;
                    finger[n] = (int8_t)k;
                    travel[n] = t;
                }
                n++;
            }
        }
    }
    starts[size] = n;
    return n;
}

static PyObject *
slide_table_py(PyObject *Py_UNUSED(self), PyObject *args)
{
    Py_buffer touching, of0, start0, members0, of1, start1, members1, x, y, starts, b[3];
    double max_travel;
    memset(b, 0, sizeof(b));
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*y*y*y*dw*|w*w*w*", &touching, &of0, &start0, &members0, &of1, &start1,
                          &members1, &x, &y, &max_travel, &starts, &b[0], &b[1], &b[2]))
        return NULL;
    const char *name = "slide_table";
    PyObject *result = NULL;
    Py_buffer *all[] = {&touching, &of0, &start0, &members0, &of1, &start1, &members1, &x, &y, &starts, &b[0], &b[1],
                        &b[2]};
    Py_ssize_t L = (Py_ssize_t)sizeof(int64_t), I = (Py_ssize_t)sizeof(int32_t), D = (Py_ssize_t)sizeof(double);
    Py_ssize_t size = x.len / D;
    Py_buffer *ofs[2] = {&of0, &of1}, *sts[2] = {&start0, &start1}, *mem[2] = {&members0, &members1};
    if (!check(&x, D, size, name, "x") || !check(&y, D, size, name, "y") || !check(&touching, 1, 2 * size, name, "touching")
        || !check(&starts, L, size + 1, name, "starts"))
        goto done;
    const int64_t *of[2], *start[2], *members[2];
    for (int k = 0; k < 2; k++) {
        Py_ssize_t groups = sts[k]->len / L - 1, count = mem[k]->len / L;
        if (!check(ofs[k], L, size, name, "of") || groups < 0 || !check(sts[k], L, groups + 1, name, "start")
            || !check(mem[k], L, count, name, "members"))
            goto done;
        of[k] = ofs[k]->buf;
        start[k] = sts[k]->buf;
        members[k] = mem[k]->buf;
        for (Py_ssize_t g = 0; g < size; g++) {
            if (of[k][g] < -1 || of[k][g] >= groups) {
                PyErr_Format(PyExc_ValueError, "%s: a group outside [-1, %zd)", name, groups);
                goto done;
            }
        }
        for (Py_ssize_t i = 0; i <= groups; i++) {
            if (start[k][i] < 0 || start[k][i] > count || (i > 0 && start[k][i] < start[k][i - 1])) {
                PyErr_Format(PyExc_ValueError, "%s: group starts must rise within [0, %zd]", name, count);
                goto done;
            }
        }
        for (Py_ssize_t i = 0; i < count; i++) {
            if (members[k][i] < 0 || members[k][i] >= size) {
                PyErr_Format(PyExc_ValueError, "%s: a member outside [0, %zd)", name, size);
                goto done;
            }
        }
    }
    int fill = b[0].obj != NULL;
    Py_ssize_t n;
    if (fill) {
        if (b[2].obj == NULL) {
            PyErr_SetString(PyExc_TypeError, "slide_table: dst, finger and travel, or none of them");
            goto done;
        }
        Py_ssize_t cap = b[0].len / I;
        if (!check(&b[0], I, cap, name, "dst") || !check(&b[1], 1, cap, name, "finger")
            || !check(&b[2], D, cap, name, "travel"))
            goto done;
        Py_BEGIN_ALLOW_THREADS
        n = slides_of(touching.buf, of, start, members, x.buf, y.buf, max_travel, size, starts.buf, NULL, NULL, NULL);
        Py_END_ALLOW_THREADS
        if (n != cap) {
            PyErr_Format(PyExc_ValueError, "%s: %zd slides, room for %zd", name, n, cap);
            goto done;
        }
        if (n > INT32_MAX) {
            PyErr_Format(PyExc_ValueError, "%s: more than 2^31 - 1 slides", name);
            goto done;
        }
        Py_BEGIN_ALLOW_THREADS
        n = slides_of(touching.buf, of, start, members, x.buf, y.buf, max_travel, size, starts.buf, b[0].buf, b[1].buf,
                      b[2].buf);
        Py_END_ALLOW_THREADS
    } else {
        Py_BEGIN_ALLOW_THREADS
        n = slides_of(touching.buf, of, start, members, x.buf, y.buf, max_travel, size, starts.buf, NULL, NULL, NULL);
        Py_END_ALLOW_THREADS
    }
    result = PyLong_FromSsize_t(n);
done:
    release(all, sizeof(all) / sizeof(all[0]));
    return result;
}

static PyMethodDef methods[] = {
    {"relax", relax_py, METH_VARARGS,
     "relax(cost, other, valid, order, keys, heads, h0, out): Bellman-Ford rounds of the grasp graph's "
     "optimistic passes, out[r] = minimum(prev, best) (the numpy form in grasp_graph._Optimistic._rounds)."},
    {"spread", spread_py, METH_VARARGS,
     "spread(cost, other, valid, order, keys, heads, h0, out): the forward rounds over the same source groups, "
     "out[r] = minimum(prev, best) with best[other[j]] the least cost[j] + prev[source] (the numpy form in "
     "grasp_graph._Optimistic._rounds groups by destination)."},
    {"counting_order", counting_order_py, METH_VARARGS,
     "counting_order(keys, order, starts): the stable order of keys in [0, len(starts) - 1) and where each "
     "key's run starts in it."},
    {"layer_order", layer_order_py, METH_VARARGS,
     "layer_order(srcs, dsts, costs, order, starts, dst, cost): the primitives' candidate edges in one order by "
     "source (grasp_graph._LayerGraph.of): the order of the indices, where each source's run starts, and the "
     "destinations (int32) and costs in that order."},
    {"near_best", near_best_py, METH_VARARGS,
     "near_best(valid, order, keys, heads, dst, cost, fwd, bwd, bound, out, f): the positions of the unchecked edges "
     "whose optimistic path through them costs at most bound (grasp_graph._select) and those costs, into out and f; "
     "returns how many."},
    {"slide_table", slide_table_py, METH_VARARGS,
     "slide_table(touching, of0, start0, members0, of1, start1, members1, x, y, max_travel, starts[, dst, finger, "
     "travel]): every slide of a grasp set by source, from its slide groups (adjust_grasp.Slide._table): fills "
     "starts and returns how many; with dst, finger and travel for that many, fills them too."},
    {"select_pairs", select_pairs_py, METH_VARARGS,
     "select_pairs(starts, dst, rows, members[, sense, finger, travel, out_src, out_dst, out_sense, out_finger, "
     "out_travel]): how many pairs of the sources rows have their destination in members; with the outputs, "
     "those pairs copied out in the table's order."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "ldhp_tamp._search",
    "Compiled array passes of the grasp graph's search (optional; numpy computes without it).",
    -1, methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC
PyInit__search(void)
{
    PyObject *m = PyModule_Create(&module);
    if (m != NULL && PyModule_AddIntConstant(m, "API", API_VERSION) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
