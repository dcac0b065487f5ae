/*
 * geometry._kernels: compiled twins of a few checks of the geometric backend, each
 * making numpy's floating-point operations in numpy's order (built with
 * -ffp-contract=off: no fused multiply-adds), so that both decide every input alike;
 * tests pin each to its numpy rule (tests/geometry/test_kernels.py). geometry.compiled
 * loads the module (or not: numpy decides alone).
 *
 *  - contains(), feasible(): the cone test and the fused feasibility test of
 *    geometry.mechanics (below);
 *  - convex_overlap(): the exact-sign overlap of strictly convex polygons with a
 *    target's boundary (geometry.collision._convex_vs_target_numpy);
 *  - pair_tests(): the principal-contact tests of an object's features against the
 *    environment's (geometry.contacts._pair_tests_numpy).
 *
 * The cone test. contains(X, Y, Z, T, out, cross_tol, det_tol, degenerate_tol) decides
 * for each instance i of a chunk whether the target T[:, i] lies in the cone of the
 * generators (X[k, i], Y[k, i], Z[k, i]), k < K: the rule of
 * geometry.mechanics._contains_numpy, instance by instance. What the compiled loops save
 * is numpy's passes over whole arrays: a block of instances stops once all hold a
 * certificate, and the block's working set stays in the L1 cache.
 *
 * The rule (geometry/mechanics.py, _reduce_to_ey and _contains_reduced):
 *  - map the instance linearly so that its target becomes a positive multiple of e_y
 *    (a coordinate permutation putting the largest |component| in the middle, a sign,
 *    then a shear); a zero target is in every cone;
 *  - the generator slots zero in every instance of the chunk are left out ("live");
 *  - a triple (i, j, k) of live generators certifies iff the crosses
 *    c_jk = P_j Q_k - Q_j P_k have the signs of a positive combination and the
 *    determinant D = A_i c_jk - A_j c_ik + A_k c_ij has the same sign, beyond the
 *    tolerances;
 *  - otherwise, where some pair's |c_jk| <= 3 degenerate_tol (or fewer than three slots
 *    are live), the one- and two-generator certificates are tried.
 *
 * Buffers are C-ordered doubles: X, Y, Z of shape (K, b), T of shape (3, b); out is b
 * bytes (1 = contained). The GIL is released while deciding.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

/* the interface geometry.compiled expects (its API) */
#define API_VERSION 4

/* the most generator slots a chunk may have (contacts x 2); more go to numpy */
#define MAX_SLOTS 16

static double
sign_of(double x)
{
    /* numpy.sign on finite values */
    return x > 0.0 ? 1.0 : (x < 0.0 ? -1.0 : 0.0);
}

/* the one- and two-generator certificates (mechanics._contains_degenerate) */
static int
degenerate(const double *P, const double *Q, const double *A, int n, double tol)
{
    double tol2 = tol * tol;
    double nrm[MAX_SLOTS];
    for (int k = 0; k < n; k++) {
        double n2 = P[k] * P[k] + Q[k] * Q[k];
        if (A[k] > 0.0 && n2 <= tol2 * A[k] * A[k])
            return 1;
        nrm[k] = sqrt(n2);
    }
    for (int j = 0; j < n; j++) {
        for (int k = j + 1; k < n; k++) {
            double rx = nrm[k] * P[j] + nrm[j] * P[k];
            double ry = nrm[k] * Q[j] + nrm[j] * Q[k];
            double h = nrm[k] * A[j] + nrm[j] * A[k];
            if (h > 0.0 && rx * rx + ry * ry <= tol2 * h * h)
                return 1;
        }
    }
    return 0;
}

/* instances decided together: their reduced generators and crosses stay in L1 cache, and
   the loops over them (innermost) are vector loops without branches */
#define BLOCK 32

typedef long long mask_t; /* a lane-wide truth value, as wide as a double */

/* the target's map to e_y, instance by instance: the shear (a, c) and, where the largest
   |component| is not a positive y, the permutation (kx, kz) and sign; 0 = none needed,
   1 = permuted, 2 = a zero target */
static int
target_map(double tx, double ty, double tz, double *a, double *c, int *kx, int *kz, double *sgn)
{
    double ax = fabs(tx), ay = fabs(ty), az = fabs(tz);
    *kx = 0;
    *kz = 0;
    *sgn = 1.0;
    if (ty > 0.0 && ty >= ax && ty >= az) {
        *a = tx / ty;
        *c = tz / ty;
        return 0;
    }
    double top = ax > ay ? ax : ay;
    top = top > az ? top : az;
    if (top == 0.0) {
        *a = 0.0;
        *c = 0.0;
        return 2;
    }
    int x = ax >= ay && ax >= az;
    int z = !x && az > ay;
    double s = x ? sign_of(tx) : (z ? sign_of(tz) : sign_of(ty));
    double u = x ? ty : tx;
    double v = (x ? tx : (z ? tz : ty)) * s;
    double w = z ? ty : tz;
    *kx = x;
    *kz = z;
    *sgn = s;
    *a = u / v;
    *c = w / v;
    return 1;
}

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
/* AVX2 where the processor has it, SSE2 otherwise (chosen when the module loads) */
#define VECTOR_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define VECTOR_CLONES
#endif

/* one block of m <= BLOCK instances starting at i0 */
VECTOR_CLONES static void
decide_block(const double *X, const double *Y, const double *Z, const double *T, unsigned char *out,
             Py_ssize_t b, Py_ssize_t i0, int m, const int *live, int n, double cross_tol, double det_tol,
             double deg_tol)
{
    double P[MAX_SLOTS][BLOCK], Q[MAX_SLOTS][BLOCK], A[MAX_SLOTS][BLOCK];
    double C[MAX_SLOTS * (MAX_SLOTS - 1) / 2][BLOCK];
    double sa[BLOCK], sc[BLOCK];
    mask_t hit[BLOCK], near[BLOCK];
    unsigned char zero[BLOCK];
    int kxs[BLOCK], kzs[BLOCK];
    double sgns[BLOCK];
    int permuted = 0;
    for (int i = 0; i < m; i++) {
        Py_ssize_t at = i0 + i;
        int how = target_map(T[at], T[b + at], T[2 * b + at], &sa[i], &sc[i], &kxs[i], &kzs[i], &sgns[i]);
        zero[i] = how == 2;
        permuted |= how != 0;
    }
    for (int g = 0; g < n; g++) {
        const double *x = X + live[g] * b + i0, *y = Y + live[g] * b + i0, *z = Z + live[g] * b + i0;
        if (!permuted) {
            for (int i = 0; i < m; i++) {
                P[g][i] = x[i] - sa[i] * y[i];
                Q[g][i] = z[i] - sc[i] * y[i];
                A[g][i] = y[i];
            }
        }
        else {
            for (int i = 0; i < m; i++) {
                double xp = kxs[i] ? y[i] : x[i];
                double yp = (kxs[i] ? x[i] : (kzs[i] ? z[i] : y[i])) * sgns[i];
                double zp = kzs[i] ? y[i] : z[i];
                P[g][i] = xp - sa[i] * yp;
                Q[g][i] = zp - sc[i] * yp;
                A[g][i] = yp;
            }
        }
    }
    for (int i = 0; i < m; i++) {
        hit[i] = 0;
        near[i] = n < 3;
    }
    if (n >= 3) {
        double small = 3.0 * deg_tol;
        int row[MAX_SLOTS]; /* pair (j, k) is C[row[j] + k - j - 1] */
        for (int j = 0, r = 0; j < n; r += n - 1 - j, j++)
            row[j] = r;
        for (int j = 0; j < n; j++) {
            for (int k = j + 1; k < n; k++) {
                double *c = C[row[j] + k - j - 1];
                for (int i = 0; i < m; i++) {
                    double cr = P[j][i] * Q[k][i] - Q[j][i] * P[k][i];
                    c[i] = cr;
                    near[i] |= -(mask_t)(fabs(cr) <= small);
                }
            }
        }
        for (int p = 0; p < n - 2; p++) {
            for (int j = p + 1; j < n - 1; j++) {
                const double *cij = C[row[p] + j - p - 1], *Ap = A[p], *Aj = A[j];
                for (int k = j + 1; k < n; k++) {
                    const double *cjk = C[row[j] + k - j - 1], *cik = C[row[p] + k - p - 1], *Ak = A[k];
                    for (int i = 0; i < m; i++) {
                        double d = Ap[i] * cjk[i] - Aj[i] * cik[i];
                        d = d + Ak[i] * cij[i];
                        mask_t pos = (cij[i] >= -cross_tol) & (cjk[i] >= -cross_tol) & (cik[i] <= cross_tol)
                                     & (d > det_tol);
                        mask_t neg = (cij[i] <= cross_tol) & (cjk[i] <= cross_tol) & (cik[i] >= -cross_tol)
                                     & (d < -det_tol);
                        hit[i] |= pos | neg;
                    }
                }
            }
            /* the first generator's triples hold most certificates: stop when all have one */
            mask_t all = 1;
            for (int i = 0; i < m; i++)
                all &= hit[i];
            if (all)
                break;
        }
    }
    for (int i = 0; i < m; i++) {
        int found = hit[i] != 0 || zero[i];
        if (!found && near[i] && n) {
            double p[MAX_SLOTS], q[MAX_SLOTS], a[MAX_SLOTS];
            for (int g = 0; g < n; g++) {
                p[g] = P[g][i];
                q[g] = Q[g][i];
                a[g] = A[g][i];
            }
            found = degenerate(p, q, a, n, deg_tol);
        }
        out[i0 + i] = (unsigned char)found;
    }
}

static void
decide(const double *X, const double *Y, const double *Z, const double *T, unsigned char *out,
       Py_ssize_t K, Py_ssize_t b, double cross_tol, double det_tol, double deg_tol)
{
    /* the generator slots not zero in every instance of the chunk */
    int live[MAX_SLOTS];
    int n = 0;
    for (Py_ssize_t k = 0; k < K; k++) {
        const double *x = X + k * b, *y = Y + k * b, *z = Z + k * b;
        for (Py_ssize_t i = 0; i < b; i++) {
            if (x[i] != 0.0 || y[i] != 0.0 || z[i] != 0.0) {
                live[n++] = (int)k;
                break;
            }
        }
    }
    for (Py_ssize_t i0 = 0; i0 < b; i0 += BLOCK) {
        int m = (int)(b - i0 < BLOCK ? b - i0 : BLOCK);
        decide_block(X, Y, Z, T, out, b, i0, m, live, n, cross_tol, det_tol, deg_tol);
    }
}

/*
 * The fused feasibility test (mechanics._feasible_impl's rule): for each instance, the
 * generators of its contacts' mode-dependent friction cones (mechanics._generators_chunk),
 * the target e_y shifted by the margin (mechanics._shifted_target), then decide() on
 * chunks of `chunk` instances (the generator slots left out are those zero in every
 * instance of a chunk, as in numpy), and no instance with a PENETRATING contact.
 * Every value is computed with numpy's operations in numpy's order.
 */
typedef struct {
    const double *points, *normals, *mu, *slides, *com, *inv_L, *margin;
    const signed char *modes;
    Py_ssize_t B, C, com_n, inv_L_n, margin_n;
    int sticking, rolling, sliding, penetrating;
    double mu_zero;
} Feasible;

VECTOR_CLONES static void
build_chunk(const Feasible *f, Py_ssize_t s, Py_ssize_t b, double *X, double *Y, double *Z, double *T,
            unsigned char *pen)
{
    Py_ssize_t C = f->C, K = 2 * C;
    for (Py_ssize_t i = 0; i < b; i++) {
        pen[i] = 0;
        T[i] = 0.0;
        T[b + i] = 0.0;
        T[2 * b + i] = 0.0;
    }
    for (Py_ssize_t c = 0; c < C; c++) {
        double *x0 = X + (2 * c) * b, *x1 = X + (2 * c + 1) * b;
        double *y0 = Y + (2 * c) * b, *y1 = Y + (2 * c + 1) * b;
        double *z0 = Z + (2 * c) * b, *z1 = Z + (2 * c + 1) * b;
        for (Py_ssize_t i = 0; i < b; i++) {
            Py_ssize_t g = s + i, at = g * C + c;
            double px = f->points[2 * at], py = f->points[2 * at + 1];
            double nx = f->normals[2 * at], ny = f->normals[2 * at + 1];
            double mus = f->mu[at];
            int md = f->modes[at];
            double mu = mus < f->mu_zero ? 0.0 : mus;
            const double *com = f->com + (f->com_n > 1 ? 2 * g : 0);
            double il = f->inv_L[f->inv_L_n > 1 ? g : 0];
            double rx = (px - com[0]) * il, ry = (py - com[1]) * il;
            double mny = mu * ny, mnx = mu * nx;
            double root = sqrt(mu * mu + 1.0);
            int full = md == f->sticking || md == f->rolling;
            int sliding = md == f->sliding;
            double inv = (full ? 1.0 : 0.0) / root;
            /* edge 1: n - mu t */
            double X1 = (nx + mny) * inv, Y1 = (ny - mnx) * inv;
            /* edge 0: n + mA t, mA = mu, or -sign(s.t) mu when sliding (the edge opposing it) */
            double sdx = f->slides[2 * at], sdy = f->slides[2 * at + 1];
            double st = -sdx * ny + sdy * nx;
            double mA = sliding ? -sign_of(st) * mu : mu;
            double invA = sliding ? 1.0 / sqrt(1.0 + mA * mA) : inv;
            double X0 = (nx - mA * ny) * invA, Y0 = (ny + mA * nx) * invA;
            x0[i] = X0;
            y0[i] = Y0;
            z0[i] = rx * Y0 - ry * X0;
            x1[i] = X1;
            y1[i] = Y1;
            z1[i] = rx * Y1 - ry * X1;
            pen[i] |= md == f->penetrating;
        }
    }
    /* target e_y - eps * (sum of the generators, in slot order from zero) */
    for (Py_ssize_t k = 0; k < K; k++) {
        for (Py_ssize_t i = 0; i < b; i++) {
            T[i] += X[k * b + i];
            T[b + i] += Y[k * b + i];
            T[2 * b + i] += Z[k * b + i];
        }
    }
    for (Py_ssize_t i = 0; i < b; i++) {
        double eps = f->margin[f->margin_n > 1 ? s + i : 0];
        T[i] = 0.0 - T[i] * eps;
        T[b + i] = 1.0 - T[b + i] * eps;
        T[2 * b + i] = 0.0 - T[2 * b + i] * eps;
    }
}

/* whether every buffer of a call is C-contiguous; else a ValueError naming the call */
static int
contiguous(Py_buffer *const *all, size_t n, const char *name)
{
    for (size_t q = 0; q < n; q++) {
        if (!PyBuffer_IsContiguous(all[q], 'C')) {
            PyErr_Format(PyExc_ValueError, "%s: buffers must be C-contiguous", name);
            return 0;
        }
    }
    return 1;
}

static void
release(Py_buffer *const *all, size_t n)
{
    for (size_t q = 0; q < n; q++)
        PyBuffer_Release(all[q]);
}

#define COUNT(a) (sizeof(a) / sizeof((a)[0]))

static PyObject *
feasible_py(PyObject *Py_UNUSED(self), PyObject *args)
{
    Py_buffer pts, nrm, mu, modes, slides, com, inv_L, margin, out;
    Py_ssize_t chunk;
    int sticking, rolling, sliding, penetrating;
    double mu_zero, cross_tol, det_tol, deg_tol;
    if (!PyArg_ParseTuple(args, "y*y*y*y*y*y*y*y*w*n(iiii)dddd", &pts, &nrm, &mu, &modes, &slides, &com, &inv_L,
                          &margin, &out, &chunk, &sticking, &rolling, &sliding, &penetrating, &mu_zero, &cross_tol,
                          &det_tol, &deg_tol))
        return NULL;
    PyObject *result = NULL;
    double *work = NULL;
    Py_buffer *all[] = {&pts, &nrm, &mu, &modes, &slides, &com, &inv_L, &margin, &out};
    Py_ssize_t B = out.len, D = (Py_ssize_t)sizeof(double);
    Py_ssize_t C = B ? mu.len / D / B : 0;
    if (!contiguous(all, COUNT(all), "feasible"))
        goto done;
    if (mu.len != B * C * D || pts.len != 2 * mu.len || nrm.len != pts.len || slides.len != pts.len
        || modes.len != B * C || (com.len != 2 * D && com.len != 2 * B * D)
        || (inv_L.len != D && inv_L.len != B * D) || (margin.len != D && margin.len != B * D) || chunk < 1) {
        PyErr_SetString(PyExc_ValueError, "feasible: points, normals and slides must be (B, C, 2) doubles, mu (B, C) "
                                          "doubles, modes (B, C) bytes, com (2) or (B, 2), inv_L and margin (1) or "
                                          "(B), out B bytes");
        goto done;
    }
    if (2 * C > MAX_SLOTS) {
        PyErr_Format(PyExc_ValueError, "feasible: at most %d generator slots", MAX_SLOTS);
        goto done;
    }
    if (B == 0 || C == 0) {
        memset(out.buf, 0, (size_t)B);
        result = Py_NewRef(Py_None);
        goto done;
    }
    Feasible f = {pts.buf, nrm.buf, mu.buf, slides.buf, com.buf, inv_L.buf, margin.buf, modes.buf,
                  B, C, com.len / D / 2, inv_L.len / D, margin.len / D,
                  sticking, rolling, sliding, penetrating, mu_zero};
    Py_ssize_t n = chunk < B ? chunk : B;
    work = PyMem_RawMalloc((size_t)((3 * 2 * C + 3) * n) * sizeof(double) + (size_t)n);
    if (work == NULL) {
        PyErr_NoMemory();
        goto done;
    }
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t s = 0; s < B; s += chunk) {
        Py_ssize_t b = B - s < chunk ? B - s : chunk;
        double *X = work, *Y = X + 2 * C * b, *Z = Y + 2 * C * b, *T = Z + 2 * C * b;
        unsigned char *pen = (unsigned char *)(T + 3 * b), *o = (unsigned char *)out.buf + s;
        build_chunk(&f, s, b, X, Y, Z, T, pen);
        decide(X, Y, Z, T, o, 2 * C, b, cross_tol, det_tol, deg_tol);
        for (Py_ssize_t i = 0; i < b; i++)
            o[i] &= (unsigned char)!pen[i];
    }
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    PyMem_RawFree(work);
    release(all, COUNT(all));
    return result;
}

/*
 * The overlap of strictly convex polygons with a target's boundary by exact orientation
 * signs (geometry.collision._convex_vs_target's rule): for each polygon, every target
 * edge whose bounding box meets the polygon's is tested with Shewchuk's filtered
 * orient2d signs; a certain crossing, or a target edge whose start lies certainly
 * inside the polygon, is a hit; a polygon none of whose edge pairs is a hit is decided
 * (a miss) when every pair is certainly apart, and left undecided otherwise.
 */
static int
orient_sign(double ax, double ay, double bx, double by, double cx, double cy, double err, double floor_)
{
    double left = (ax - cx) * (by - cy);
    double right = (ay - cy) * (bx - cx);
    double det = left - right;
    double bound = err * (fabs(left) + fabs(right)) + floor_;
    return (det > bound) - (det < -bound);
}

#define MAX_POLYGON 64

static void
convex_overlap(const double *P, Py_ssize_t B, Py_ssize_t V, const double *S, const double *E, const double *lo,
               const double *hi, Py_ssize_t K, double err, double floor_, unsigned char *hit, unsigned char *decided)
{
    signed char oc[MAX_POLYGON], od[MAX_POLYGON], oa[MAX_POLYGON];
    for (Py_ssize_t b = 0; b < B; b++) {
        const double *A = P + b * V * 2;
        double plox = A[0], ploy = A[1], phix = A[0], phiy = A[1];
        for (Py_ssize_t i = 1; i < V; i++) {
            double x = A[2 * i], y = A[2 * i + 1];
            plox = x < plox ? x : plox;
            phix = x > phix ? x : phix;
            ploy = y < ploy ? y : ploy;
            phiy = y > phiy ? y : phiy;
        }
        int any_hit = 0, unsure = 0;
        for (Py_ssize_t k = 0; k < K && !any_hit; k++) {
            if (!(lo[2 * k] <= phix && hi[2 * k] >= plox && lo[2 * k + 1] <= phiy && hi[2 * k + 1] >= ploy))
                continue;
            double cx = S[2 * k], cy = S[2 * k + 1], dx = E[2 * k], dy = E[2 * k + 1];
            for (Py_ssize_t i = 0; i < V; i++) {
                Py_ssize_t j = i + 1 < V ? i + 1 : 0;
                double ax = A[2 * i], ay = A[2 * i + 1], bx = A[2 * j], by = A[2 * j + 1];
                oc[i] = (signed char)orient_sign(ax, ay, bx, by, cx, cy, err, floor_);
                od[i] = (signed char)orient_sign(ax, ay, bx, by, dx, dy, err, floor_);
                oa[i] = (signed char)orient_sign(cx, cy, dx, dy, ax, ay, err, floor_);
            }
            int cross = 0, all_left = 1, apart = 1, some_right = 0;
            for (Py_ssize_t i = 0; i < V; i++) {
                int cd = oc[i] * od[i], ab = oa[i] * oa[i + 1 < V ? i + 1 : 0];
                cross |= cd < 0 && ab < 0;
                all_left &= oc[i] > 0;
                apart &= cd > 0 || ab > 0;
                some_right |= oc[i] < 0;
            }
            int pair_hit = cross || all_left;
            int pair_miss = apart && some_right;
            any_hit |= pair_hit;
            unsure |= !pair_hit && !pair_miss;
        }
        hit[b] = (unsigned char)any_hit;
        decided[b] = (unsigned char)(any_hit || !unsure);
    }
}

static PyObject *
convex_overlap_py(PyObject *Py_UNUSED(self), PyObject *args)
{
    Py_buffer P, S, E, lo, hi, hit, decided;
    Py_ssize_t V;
    double err, floor_;
    if (!PyArg_ParseTuple(args, "y*ny*y*y*y*w*w*dd", &P, &V, &S, &E, &lo, &hi, &hit, &decided, &err, &floor_))
        return NULL;
    PyObject *result = NULL;
    Py_buffer *all[] = {&P, &S, &E, &lo, &hi, &hit, &decided};
    Py_ssize_t D = (Py_ssize_t)sizeof(double), B = hit.len, K = S.len / D / 2;
    if (!contiguous(all, COUNT(all), "convex_overlap"))
        goto done;
    if (V < 1 || V > MAX_POLYGON || P.len != B * V * 2 * D || decided.len != B || S.len != K * 2 * D
        || E.len != S.len || lo.len != S.len || hi.len != S.len) {
        PyErr_Format(PyExc_ValueError, "convex_overlap: polygons must be (B, V, 2) doubles with 1 <= V <= %d, "
                     "target edges' starts, ends, lows and highs (K, 2) doubles, hit and decided B bytes",
                     MAX_POLYGON);
        goto done;
    }
    Py_BEGIN_ALLOW_THREADS
    convex_overlap(P.buf, B, V, S.buf, E.buf, lo.buf, hi.buf, K, err, floor_, hit.buf, decided.buf);
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    release(all, COUNT(all));
    return result;
}

/*
 * The principal-contact tests of an object's features against the environment's
 * (geometry.contacts._pair_tests_numpy's rule): for each row x, object vertex / edge i and
 * environment edge y, the vertex-edge, edge-vertex and edge-edge tests, with u, s and
 * the edge-edge overlap interval. The environment's tables are (Xe, Y) with Xe = 1 (the
 * same edges for every row: a dense frame) or Xe = X (one edge per row).
 */
enum { E_AX, E_AY, E_TX, E_TY, E_NX, E_NY, E_LE, E_TAX, E_TAY, E_LEA, E_TABLES };

static inline double
clip(double v, double lo, double hi)
{
    /* numpy.clip: minimum(maximum(v, lo), hi) */
    double m = v > lo ? v : lo;
    return m < hi ? m : hi;
}

static inline double
dot(double ax, double ay, double bx, double by)
{
    return ax * bx + ay * by;
}

/* point p in the frame of a segment starting at o with direction t and normal n: its
   (along, across) coordinates */
static inline void
in_frame(double px, double py, double ox, double oy, double tx, double ty, double nx, double ny, double *along,
         double *across)
{
    double rx = px - ox, ry = py - oy;
    *along = dot(rx, ry, tx, ty);
    *across = dot(rx, ry, nx, ny);
}

/* a point at (along, across) from a segment's start, in the segment's frame, lies within
   sqrt(tol2) of the segment of that length */
static inline int
near_segment(double along, double across, double length, double tol2)
{
    double c = clip(along, 0.0, length);
    return (along - c) * (along - c) + across * across <= tol2;
}

/* both features leaving a contact point stay on the free side of the other's line: each
   far end (at lengths la, lb) at most tol below it */
static inline int
free_side(double a, double la, double b, double lb, double tol)
{
    return a >= -tol / la && b >= -tol / lb;
}

static void
pair_tests(const double *V, const double *D, const double *Nn, Py_ssize_t X, Py_ssize_t N, Py_ssize_t Y,
           const double *env, const unsigned char *env_convex, Py_ssize_t Xe, const double *Lo,
           const unsigned char *obj_convex, double tol, double eps, double *u_out, double *s_out, double *lo_out,
           double *hi_out, unsigned char *ve_out, unsigned char *ev_out, unsigned char *ee_out)
{
    double tol2 = tol * tol;
    Py_ssize_t ET = Xe * Y; /* one environment table's length */
    for (Py_ssize_t x = 0; x < X; x++) {
        const double *Vx = V + x * N * 2, *Dx = D + x * N * 2, *Nx = Nn + x * N * 2;
        Py_ssize_t e0 = (Xe > 1 ? x : 0) * Y;
        for (Py_ssize_t i = 0; i < N; i++) {
            Py_ssize_t ip = i > 0 ? i - 1 : N - 1, in = i + 1 < N ? i + 1 : 0;
            double vx = Vx[2 * i], vy = Vx[2 * i + 1], dx = Dx[2 * i], dy = Dx[2 * i + 1];
            double nx = Nx[2 * i], ny = Nx[2 * i + 1];
            double pdx = Dx[2 * ip], pdy = Dx[2 * ip + 1];
            double qx = Vx[2 * in], qy = Vx[2 * in + 1]; /* v_(i+1): u and s at the edge's end */
            double lo_i = Lo[i], lo_p = Lo[ip];
            for (Py_ssize_t y = 0; y < Y; y++) {
                Py_ssize_t e = e0 + y, at = (x * N + i) * Y + y;
                double Ax = env[E_AX * ET + e], Ay = env[E_AY * ET + e];
                double Tx = env[E_TX * ET + e], Ty = env[E_TY * ET + e];
                double Nex = env[E_NX * ET + e], Ney = env[E_NY * ET + e];
                double Le = env[E_LE * ET + e];
                double Tax = env[E_TAX * ET + e], Tay = env[E_TAY * ET + e], Lea = env[E_LEA * ET + e];
                double u, s, eu, es, uQ, sQ;
                /* vertex-edge: object vertex i vs environment edge y */
                in_frame(vx, vy, Ax, Ay, Tx, Ty, Nex, Ney, &u, &s);
                ve_out[at] = (unsigned char)(near_segment(u, s, Le, tol2)
                                             && free_side(dot(dx, dy, Nex, Ney), lo_i, -dot(pdx, pdy, Nex, Ney), lo_p,
                                                          tol)
                                             && obj_convex[i]);
                /* edge-vertex: environment vertex y (the start of edge y) vs object edge i */
                in_frame(Ax, Ay, vx, vy, dx, dy, nx, ny, &eu, &es);
                ev_out[at] = (unsigned char)(near_segment(eu, es, lo_i, tol2)
                                             && free_side(dot(nx, ny, Tx, Ty), Le, -dot(nx, ny, Tax, Tay), Lea, tol)
                                             && env_convex[e]);
                /* edge-edge: object edge i (v_i -> v_(i+1)) vs environment edge y */
                in_frame(qx, qy, Ax, Ay, Tx, Ty, Nex, Ney, &uQ, &sQ);
                int facing = dot(nx, ny, Nex, Ney) < 0.0;
                double mn = u < uQ ? u : uQ, mx = u > uQ ? u : uQ;
                double lo = mn > 0.0 ? mn : 0.0;
                double hi = mx < Le ? mx : Le;
                double denom = uQ - u;
                int ok = facing && hi - lo > tol && fabs(denom) > eps;
                double safe = ok ? denom : 1.0;
                double s_lo = s + (sQ - s) * (lo - u) / safe;
                double s_hi = s + (sQ - s) * (hi - u) / safe;
                ee_out[at] = (unsigned char)(ok && fabs(s_lo) <= tol && fabs(s_hi) <= tol);
                u_out[at] = u;
                s_out[at] = s;
                lo_out[at] = lo;
                hi_out[at] = hi;
            }
        }
    }
}

static PyObject *
pair_tests_py(PyObject *Py_UNUSED(self), PyObject *args)
{
    Py_buffer V, D, Nn, env, env_convex, Lo, obj_convex, u, s, lo, hi, ve, ev, ee;
    Py_ssize_t X, N, Y, Xe;
    double tol, eps;
    if (!PyArg_ParseTuple(args, "y*y*y*nnny*y*ny*y*ddw*w*w*w*w*w*w*", &V, &D, &Nn, &X, &N, &Y, &env, &env_convex,
                          &Xe, &Lo, &obj_convex, &tol, &eps, &u, &s, &lo, &hi, &ve, &ev, &ee))
        return NULL;
    PyObject *result = NULL;
    Py_buffer *all[] = {&V, &D, &Nn, &env, &env_convex, &Lo, &obj_convex, &u, &s, &lo, &hi, &ve, &ev, &ee};
    Py_ssize_t Dz = (Py_ssize_t)sizeof(double), cells = X * N * Y;
    if (!contiguous(all, COUNT(all), "pair_tests"))
        goto done;
    if (X < 0 || N < 1 || Y < 0 || (Xe != 1 && Xe != X) || V.len != X * N * 2 * Dz || D.len != V.len
        || Nn.len != V.len || env.len != E_TABLES * Xe * Y * Dz || env_convex.len != Xe * Y || Lo.len != N * Dz
        || obj_convex.len != N || u.len != cells * Dz || s.len != u.len || lo.len != u.len || hi.len != u.len
        || ve.len != cells || ev.len != cells || ee.len != cells) {
        PyErr_SetString(PyExc_ValueError, "pair_tests: object arrays must be (X, N, 2) doubles, the environment's "
                                          "tables (10, Xe, Y) doubles and (Xe, Y) bytes with Xe 1 or X, the "
                                          "outputs (X, N, Y)");
        goto done;
    }
    Py_BEGIN_ALLOW_THREADS
    pair_tests(V.buf, D.buf, Nn.buf, X, N, Y, env.buf, env_convex.buf, Xe, Lo.buf, obj_convex.buf, tol, eps, u.buf,
               s.buf, lo.buf, hi.buf, ve.buf, ev.buf, ee.buf);
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    release(all, COUNT(all));
    return result;
}

static PyObject *
cone_contains_py(PyObject *Py_UNUSED(self), PyObject *args)
{
    Py_buffer X, Y, Z, T, out;
    double cross_tol, det_tol, deg_tol;
    if (!PyArg_ParseTuple(args, "y*y*y*y*w*ddd", &X, &Y, &Z, &T, &out, &cross_tol, &det_tol, &deg_tol))
        return NULL;
    PyObject *result = NULL;
    Py_buffer *all[] = {&X, &Y, &Z, &T, &out};
    Py_ssize_t b = out.len;
    Py_ssize_t K = b ? X.len / (Py_ssize_t)sizeof(double) / b : 0;
    if (!contiguous(all, COUNT(all), "contains"))
        goto done;
    if (X.len != K * b * (Py_ssize_t)sizeof(double) || Y.len != X.len || Z.len != X.len
        || T.len != 3 * b * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "contains: X, Y, Z must be (K, b) and T (3, b) doubles, out b bytes");
        goto done;
    }
    if (K > MAX_SLOTS) {
        PyErr_Format(PyExc_ValueError, "contains: at most %d generator slots", MAX_SLOTS);
        goto done;
    }
    Py_BEGIN_ALLOW_THREADS
    decide((const double *)X.buf, (const double *)Y.buf, (const double *)Z.buf, (const double *)T.buf,
           (unsigned char *)out.buf, K, b, cross_tol, det_tol, deg_tol);
    Py_END_ALLOW_THREADS
    result = Py_NewRef(Py_None);
done:
    release(all, COUNT(all));
    return result;
}

static PyMethodDef methods[] = {
    {"contains", cone_contains_py, METH_VARARGS,
     "contains(X, Y, Z, T, out, cross_tol, det_tol, degenerate_tol): out[i] = 1 iff T[:, i] is "
     "in the cone of the generators (X, Y, Z)[:, i] (geometry.mechanics._contains_numpy's rule)."},
    {"feasible", feasible_py, METH_VARARGS,
     "feasible(points, normals, mu, modes, slide_dirs, com, inv_L, margin, out, chunk, (sticking, rolling, "
     "sliding, penetrating), mu_zero, cross_tol, det_tol, degenerate_tol): out[i] = 1 iff instance i's weight is "
     "balanced with the margin (geometry.mechanics._feasible_impl's rule)."},
    {"convex_overlap", convex_overlap_py, METH_VARARGS,
     "convex_overlap(polygons, V, starts, ends, lows, highs, hit, decided, err, floor): the exact-sign overlap of "
     "strictly convex polygons with a target's edges (geometry.collision._convex_vs_target's rule)."},
    {"pair_tests", pair_tests_py, METH_VARARGS,
     "pair_tests(V, D, Nn, X, N, Y, env_tables, env_convex, Xe, Lo, obj_convex, tol, eps, u, s, lo, hi, ve, ev, ee): "
     "the principal-contact tests (geometry.contacts._pair_tests_numpy's rule)."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "geometry._kernels",
    "Compiled cone-membership test of geometry.mechanics (optional; numpy decides without it).",
    -1, methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC
PyInit__kernels(void)
{
    PyObject *m = PyModule_Create(&module);
    if (m != NULL && (PyModule_AddIntConstant(m, "MAX_SLOTS", MAX_SLOTS) < 0
                      || PyModule_AddIntConstant(m, "MAX_POLYGON", MAX_POLYGON) < 0
                      || PyModule_AddIntConstant(m, "API", API_VERSION) < 0)) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
