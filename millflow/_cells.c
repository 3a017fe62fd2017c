/*
 * Class-by-class solve of a row of well-mixed cells with back-mixing (millflow.mill_cells).
 *
 * For each size class i, coarsest first, the hold-up m_i over the n cells solves the
 * tridiagonal system
 *
 *     (S_i I - T^i) m_i = s_i + sum_{j<i} bS_ij m_j,
 *
 * lower/diag/upper holding the three diagonals of S_i I - T^i. The matrix is a
 * column-diagonally dominant M-matrix, so elimination without pivoting (Thomas) is
 * stable and keeps the solution non-negative. The numpy loop in millflow.mill_cells
 * (LAPACK gtsv per class) is the reference and the fallback; this module is an
 * optional build (setup.py).
 *
 * circuit_solve: the class-by-class solve of a linear flowsheet whose mills are chains
 * of equal well-mixed cells (millflow.flowsheet.structured, whose numpy loop is the
 * reference and the fallback), with its residual and the mills' error estimates.
 *
 * Arrays come through the buffer protocol (C-contiguous float64 / int64); the GIL is
 * released while computing.
 */
#include "_buffer.h"
#include <math.h>

/* Bump when the interface or the arithmetic changes (see millflow/_eigenbasis.c).
   2: circuit_solve, chain_column_sums (millflow.flowsheet.structured), population_chains
      (millflow.mill.population). */
#define KERNEL_VERSION 2

PyDoc_STRVAR(tridiagonal_classes_doc,
"tridiagonal_classes(lower, diag, upper, bS, source, holdup) -> int\n\n"
"lower, upper (N, n-1), diag (N, n): the diagonals of S_i I - T^i; bS (N, N) with\n"
"bS[i, j] = b_ij S_j; source (N, n, m) the feed into each cell; holdup (N, n, m) is\n"
"written. Returns 0, or the 1-based class whose elimination met a zero or non-finite\n"
"pivot (holdup is then incomplete).");

static PyObject *tridiagonal_classes(PyObject *self, PyObject *args)
{
    PyObject *olo, *odi, *oup, *obS, *osrc, *ohold;
    Py_ssize_t N, n, m;
    if (!PyArg_ParseTuple(args, "OOOOOOnnn", &olo, &odi, &oup, &obS, &osrc, &ohold, &N, &n, &m))
        return NULL;
    if (N < 0 || n < 1 || m < 1) {
        PyErr_SetString(PyExc_ValueError, "expected N >= 0 classes, n >= 1 cells, m >= 1 columns");
        return NULL;
    }
    Py_buffer vlo, vdi, vup, vbS, vsrc, vhold;
    int got = 0;
    if (get_buffer(olo, &vlo, "lower", N * (n - 1), "d", 0) < 0) goto fail;
    got = 1;
    if (get_buffer(odi, &vdi, "diag", N * n, "d", 0) < 0) goto fail;
    got = 2;
    if (get_buffer(oup, &vup, "upper", N * (n - 1), "d", 0) < 0) goto fail;
    got = 3;
    if (get_buffer(obS, &vbS, "bS", N * N, "d", 0) < 0) goto fail;
    got = 4;
    if (get_buffer(osrc, &vsrc, "source", N * n * m, "d", 0) < 0) goto fail;
    got = 5;
    if (get_buffer(ohold, &vhold, "holdup", N * n * m, "d", 1) < 0) goto fail;
    got = 6;

    const double *lo = vlo.buf, *di = vdi.buf, *up = vup.buf, *bS = vbS.buf, *src = vsrc.buf;
    double *hold = vhold.buf;
    const Py_ssize_t nm = n * m;
    double *work = PyMem_Malloc((size_t)(nm + n) * sizeof(double));
    if (!work) {
        PyErr_NoMemory();
        goto fail;
    }
    double *cp = work + nm; /* modified upper diagonal of the elimination */
    Py_ssize_t bad = 0;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < N && !bad; i++) {
        double *rhs = hold + i * nm; /* solved in place */
        memcpy(rhs, src + i * nm, (size_t)nm * sizeof(double));
        const double *brow = bS + i * N;
        for (Py_ssize_t j = 0; j < i; j++) {
            const double w = brow[j];
            if (w == 0.0)
                continue;
            const double *mj = hold + j * nm;
            for (Py_ssize_t q = 0; q < nm; q++)
                rhs[q] += w * mj[q];
        }
        const double *l = lo + i * (n - 1), *d = di + i * n, *u = up + i * (n - 1);
        /* forward elimination (Thomas), rows of rhs are cells, columns feed columns */
        double piv = d[0];
        if (!(piv != 0.0 && piv - piv == 0.0)) {
            bad = i + 1;
            break;
        }
        for (Py_ssize_t c = 0; c < m; c++)
            rhs[c] /= piv;
        for (Py_ssize_t k = 1; k < n; k++) {
            cp[k - 1] = u[k - 1] / piv;
            piv = d[k] - l[k - 1] * cp[k - 1];
            if (!(piv != 0.0 && piv - piv == 0.0)) {
                bad = i + 1;
                break;
            }
            for (Py_ssize_t c = 0; c < m; c++)
                rhs[k * m + c] = (rhs[k * m + c] - l[k - 1] * rhs[(k - 1) * m + c]) / piv;
        }
        if (bad)
            break;
        for (Py_ssize_t k = n - 2; k >= 0; k--)
            for (Py_ssize_t c = 0; c < m; c++)
                rhs[k * m + c] -= cp[k] * rhs[(k + 1) * m + c];
    }
    Py_END_ALLOW_THREADS
    PyMem_Free(work);
    PyBuffer_Release(&vlo);
    PyBuffer_Release(&vdi);
    PyBuffer_Release(&vup);
    PyBuffer_Release(&vbS);
    PyBuffer_Release(&vsrc);
    PyBuffer_Release(&vhold);
    return PyLong_FromSsize_t(bad);

fail:
    if (got > 0) PyBuffer_Release(&vlo);
    if (got > 1) PyBuffer_Release(&vdi);
    if (got > 2) PyBuffer_Release(&vup);
    if (got > 3) PyBuffer_Release(&vbS);
    if (got > 4) PyBuffer_Release(&vsrc);
    if (got > 5) PyBuffer_Release(&vhold);
    return NULL;
}

#if defined(_MSC_VER)
#define RESTRICT __restrict
#else
#define RESTRICT restrict
#endif

/* As in _eigenbasis.c: an AVX2+FMA copy of the hot loops on x86-64 Linux with gcc >= 11,
   chosen at load time; the baseline copy elsewhere. */
#if defined(__GNUC__) && __GNUC__ >= 11 && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#define HOT_LOOP __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define HOT_LOOP
#endif

/* LU of the S x S matrix a in place, partial pivoting (piv: S entries); the diagonal
   keeps the reciprocals of the pivots. Returns the smallest |pivot|, 0 for a zero or
   non-finite one. */
static double lu_small(double *a, Py_ssize_t S, Py_ssize_t *piv)
{
    double smallest = INFINITY;
    for (Py_ssize_t c = 0; c < S; c++) {
        Py_ssize_t p = c;
        double best = fabs(a[c * S + c]);
        for (Py_ssize_t r = c + 1; r < S; r++)
            if (fabs(a[r * S + c]) > best) {
                best = fabs(a[r * S + c]);
                p = r;
            }
        if (!(best > 0.0 && best - best == 0.0))
            return 0.0;
        if (best < smallest)
            smallest = best;
        piv[c] = p;
        if (p != c)
            for (Py_ssize_t q = 0; q < S; q++) {
                const double t = a[c * S + q];
                a[c * S + q] = a[p * S + q];
                a[p * S + q] = t;
            }
        const double inv = 1.0 / a[c * S + c];
        a[c * S + c] = inv;
        for (Py_ssize_t r = c + 1; r < S; r++) {
            double f = a[r * S + c];
            if (f == 0.0)
                continue;
            f *= inv;
            a[r * S + c] = f;
            for (Py_ssize_t q = c + 1; q < S; q++)
                a[r * S + q] -= f * a[c * S + q];
        }
    }
    return smallest;
}

/* Solve with the LU of lu_small, b overwritten by the solution; the flowsheet's gains
   are sparse, so zero factors are skipped. */
static inline void lu_solve_small(const double *RESTRICT a, Py_ssize_t S, const Py_ssize_t *RESTRICT piv,
                                  double *RESTRICT b)
{
    for (Py_ssize_t c = 0; c < S; c++) {
        if (piv[c] != c) {
            const double t = b[c];
            b[c] = b[piv[c]];
            b[piv[c]] = t;
        }
        const double bc = b[c];
        if (bc != 0.0)
            for (Py_ssize_t r = c + 1; r < S; r++)
                b[r] -= a[r * S + c] * bc;
    }
    for (Py_ssize_t c = S - 1; c >= 0; c--) {
        const double v = b[c] * a[c * S + c];
        b[c] = v;
        if (v != 0.0)
            for (Py_ssize_t r = 0; r < c; r++)
                b[r] -= a[r * S + c] * v;
    }
}

typedef struct {
    Py_buffer M, MT, w, ins;
    int got;
    Py_ssize_t n, o, nins;
    double *Y; /* (n, N): sums of breakage ahead, then each cell's output */
} chain_t;

/* W[c, lo:hi] += v[c] * row[lo:hi] for the n rows of W (stride N): two rows a pass (row
   loaded once for two multiply-adds; measured faster than one or four at N = 100, n = 10),
   zero multipliers skipped (the classes above the feed's top size carry nothing). */
static inline void axpy_rows(double *RESTRICT W, Py_ssize_t N, const double *RESTRICT v, Py_ssize_t n,
                             const double *RESTRICT row, Py_ssize_t lo, Py_ssize_t hi)
{
    Py_ssize_t c = 0;
    for (; c + 2 <= n; c += 2) {
        double *RESTRICT w0 = W + c * N, *RESTRICT w1 = w0 + N;
        const double v0 = v[c], v1 = v[c + 1];
        if (v0 == 0.0 && v1 == 0.0)
            continue;
        for (Py_ssize_t r = lo; r < hi; r++) {
            const double t = row[r];
            w0[r] += v0 * t;
            w1[r] += v1 * t;
        }
    }
    if (c < n && v[c] != 0.0) {
        double *RESTRICT w0 = W + c * N;
        const double v0 = v[c];
        for (Py_ssize_t r = lo; r < hi; r++)
            w0[r] += v0 * row[r];
    }
}

/* The class loop (see circuit_solve's doc): x (N, S) from the LU of every I - G_k. */
HOT_LOOP static void circuit_classes(Py_ssize_t N, Py_ssize_t S, const double *lu, const Py_ssize_t *piv,
                                     const double *src, double *x, chain_t *ch, Py_ssize_t nmills, double *consts)
{
    for (Py_ssize_t k = 0; k < N; k++) {
        double *xk = x + k * S, *a = consts;
        memcpy(xk, src + k * S, (size_t)S * sizeof(double));
        for (Py_ssize_t m = 0; m < nmills; m++) { /* a_c = (a_{c-1} - h_c) w_k; Y[c, k] holds h_c */
            const chain_t *c = ch + m;
            const double wk = ((const double *)c->w.buf)[k];
            double prev = 0.0;
            for (Py_ssize_t q = 0; q < c->n; q++) {
                prev = (prev - c->Y[q * N + k]) * wk;
                a[q] = prev;
            }
            xk[c->o] += prev;
            a += c->n;
        }
        lu_solve_small(lu + k * S * S, S, piv + k * S, xk);
        a = consts;
        for (Py_ssize_t m = 0; m < nmills; m++) { /* the cells' outputs, and their breakage ahead */
            const chain_t *c = ch + m;
            const int64_t *ins = c->ins.buf;
            double u = 0.0;
            for (Py_ssize_t i = 0; i < c->nins; i++)
                u += xk[ins[i]];
            const double wk = ((const double *)c->w.buf)[k];
            double coef = 1.0;
            for (Py_ssize_t q = 0; q < c->n; q++) {
                coef *= wk;
                a[q] = coef * u + a[q];
                c->Y[q * N + k] = a[q];
            }
            axpy_rows(c->Y, N, a, c->n, (const double *)c->MT.buf + k * N, k + 1, N);
            a += c->n;
        }
    }
}

/* n solves in turn with the lower triangular M (MT its transpose), in place: y <- M^-n y.
   Row i of every cell together: y^(c)_i = (y^(c-1)_i - sum_{j<i} M_ij y^(c)_j) / M_ii,
   the sums accumulated ahead in W (n, N, zeros on entry) by contiguous updates with
   column i of M (row i of MT) once row i is known; v (n) scratch. */
HOT_LOOP static void chain_forward(Py_ssize_t N, Py_ssize_t n, const double *M, const double *MT,
                                   double *y, double *W, double *v)
{
    for (Py_ssize_t i = 0; i < N; i++) {
        const double d = M[i * N + i];
        double prev = y[i];
        for (Py_ssize_t c = 0; c < n; c++) {
            prev = (prev - W[c * N + i]) / d;
            v[c] = prev;
        }
        axpy_rows(W, N, v, n, MT + i * N, i + 1, N);
        y[i] = prev;
    }
}

/* The transpose: z <- (M^-T)^n z, from the last class up, with the rows of M. */
HOT_LOOP static void chain_transposed(Py_ssize_t N, Py_ssize_t n, const double *M, double *z, double *W, double *v)
{
    for (Py_ssize_t i = N - 1; i >= 0; i--) {
        const double d = M[i * N + i];
        double prev = z[i];
        for (Py_ssize_t c = 0; c < n; c++) {
            prev = (prev - W[c * N + i]) / d;
            v[c] = prev;
        }
        axpy_rows(W, N, v, n, M + i * N, 0, i);
        z[i] = prev;
    }
}

PyDoc_STRVAR(chain_column_sums_doc,
"chain_column_sums(M, n) -> list\n\n"
"Column sums of the transfer matrix M^-n of a chain of n equal cells (M (N, N) lower\n"
"triangular, C-contiguous): z = (M^-T)^n 1 by n transposed triangular solves.");

static PyObject *chain_column_sums(PyObject *self, PyObject *args)
{
    PyObject *oM;
    Py_ssize_t n;
    if (!PyArg_ParseTuple(args, "On", &oM, &n))
        return NULL;
    if (n < 1) {
        PyErr_SetString(PyExc_ValueError, "expected n >= 1 cells");
        return NULL;
    }
    Py_buffer vM;
    if (get_buffer(oM, &vM, "M", -1, "d", 0) < 0)
        return NULL;
    Py_ssize_t N = (Py_ssize_t)floor(sqrt((double)(vM.len / (Py_ssize_t)sizeof(double))) + 0.5);
    if (N * N * (Py_ssize_t)sizeof(double) != vM.len) {
        PyBuffer_Release(&vM);
        PyErr_SetString(PyExc_ValueError, "M: expected a square (N, N) float64 array");
        return NULL;
    }
    double *work = PyMem_Calloc((size_t)(N * n + N + n + 1), sizeof(double));
    if (!work) {
        PyBuffer_Release(&vM);
        return PyErr_NoMemory();
    }
    double *z = work + N * n, *v = z + N;
    for (Py_ssize_t i = 0; i < N; i++)
        z[i] = 1.0;
    Py_BEGIN_ALLOW_THREADS
    chain_transposed(N, n, vM.buf, z, work, v);
    Py_END_ALLOW_THREADS
    PyObject *out = PyList_New(N);
    for (Py_ssize_t i = 0; out && i < N; i++)
        PyList_SET_ITEM(out, i, PyFloat_FromDouble(z[i]));
    PyMem_Free(work);
    PyBuffer_Release(&vM);
    return out;
}

PyDoc_STRVAR(circuit_solve_doc,
"circuit_solve(A, Gd, src, x, mills, N, S) -> (amplification, residual)\n\n"
"The class-by-class solve of a linear flowsheet whose mills are chains of equal\n"
"well-mixed cells (millflow.flowsheet.structured), and its checks. A (N, S, S) holds\n"
"I - G_k per class (read only), Gd (N, S, S) the gains of the units other\n"
"than the mills, src (N, S) the constant sources; x (N, S) is written (class-major).\n"
"mills is a sequence of (M, MT, w, o, ins, n): M (N, N) the cell matrix, MT its\n"
"transpose (C-contiguous), w = 1 / diag(M), o the outlet stream, ins (int64) the inlet\n"
"streams, n the cells.\n\n"
"In class k the breakage from coarser classes into cell c, h_c = sum_{j<k} M_kj y_c,j,\n"
"makes each cell's output affine in the mill's inlet u: y_c,k = w_k^(c+1) u + a_c,\n"
"a_c = (a_{c-1} - h_c) w_k; a_{n-1} enters the outlet's source and\n"
"x_k = (I - G_k)^-1 (src_k + those constants). h is accumulated ahead: once class k's\n"
"outputs are known, column k of M times them is added to every finer class.\n\n"
"Check: the residual max |x - (src + Gd x + each mill's M^-n inlet)| / max |src|, the\n"
"mills' outputs re-solved by n triangular solves from the solved inlet. amplification\n"
"is 1 / the smallest LU\n"
"pivot over the classes (1 / (1 - loop gain) for one recycle loop), inf (nothing\n"
"solved) when some I - G_k is singular or not finite, or when x is not finite.");

static void release_chains(chain_t *ch, Py_ssize_t count)
{
    for (Py_ssize_t m = 0; m < count; m++) {
        if (ch[m].got > 0) PyBuffer_Release(&ch[m].M);
        if (ch[m].got > 1) PyBuffer_Release(&ch[m].MT);
        if (ch[m].got > 2) PyBuffer_Release(&ch[m].w);
        if (ch[m].got > 3) PyBuffer_Release(&ch[m].ins);
    }
}

static PyObject *circuit_solve(PyObject *self, PyObject *args)
{
    PyObject *oA, *oGd, *osrc, *ox, *omills;
    Py_ssize_t N, S;
    if (!PyArg_ParseTuple(args, "OOOOOnn", &oA, &oGd, &osrc, &ox, &omills, &N, &S))
        return NULL;
    if (N < 1 || S < 1) {
        PyErr_SetString(PyExc_ValueError, "expected N >= 1 classes, S >= 1 streams");
        return NULL;
    }
    Py_buffer vA, vG, vs, vx;
    int got = 0;
    PyObject *seq = NULL, *result = NULL;
    chain_t *ch = NULL;
    double *work = NULL;
    Py_ssize_t nmills = 0, total = 0, maxn = 1;
    if (get_buffer(oA, &vA, "A", N * S * S, "d", 0) < 0) goto done;
    got = 1;
    if (get_buffer(oGd, &vG, "Gd", N * S * S, "d", 0) < 0) goto done;
    got = 2;
    if (get_buffer(osrc, &vs, "src", N * S, "d", 0) < 0) goto done;
    got = 3;
    if (get_buffer(ox, &vx, "x", N * S, "d", 1) < 0) goto done;
    got = 4;
    seq = PySequence_Fast(omills, "mills: expected a sequence of (M, MT, w, o, ins, n)");
    if (!seq)
        goto done;
    nmills = PySequence_Fast_GET_SIZE(seq);
    ch = PyMem_Calloc((size_t)(nmills ? nmills : 1), sizeof(chain_t));
    if (!ch) {
        PyErr_NoMemory();
        goto done;
    }
    for (Py_ssize_t m = 0; m < nmills; m++) {
        PyObject *item = PySequence_Fast_GET_ITEM(seq, m), *oM, *oMT, *ow, *oins;
        chain_t *c = ch + m;
        if (!PyArg_ParseTuple(item, "OOOnOn", &oM, &oMT, &ow, &c->o, &oins, &c->n))
            goto done;
        if (get_buffer(oM, &c->M, "M", N * N, "d", 0) < 0) goto done;
        c->got = 1;
        if (get_buffer(oMT, &c->MT, "MT", N * N, "d", 0) < 0) goto done;
        c->got = 2;
        if (get_buffer(ow, &c->w, "w", N, "d", 0) < 0) goto done;
        c->got = 3;
        if (get_buffer(oins, &c->ins, "ins", -1, "q", 0) < 0) goto done;
        c->got = 4;
        c->nins = c->ins.len / (Py_ssize_t)sizeof(int64_t);
        if (c->n < 1 || c->o < 0 || c->o >= S) {
            PyErr_SetString(PyExc_ValueError, "mills: expected n >= 1 cells and an outlet index in [0, S)");
            goto done;
        }
        const int64_t *ins = c->ins.buf;
        for (Py_ssize_t i = 0; i < c->nins; i++)
            if (ins[i] < 0 || ins[i] >= S) {
                PyErr_SetString(PyExc_ValueError, "ins: expected stream indices in [0, S)");
                goto done;
            }
        total += c->n;
        if (c->n > maxn)
            maxn = c->n;
    }
    /* work: Y of every mill (total N), consts (total), pred (N S), W (maxn N), y, z (N), LU (N S S),
       piv (N S); z unused */
    const size_t nwork = (size_t)(total * N + total + N * S + maxn * N + 2 * N + N * S * S);
    work = PyMem_Calloc(nwork * sizeof(double) + (size_t)(N * S) * sizeof(Py_ssize_t), 1);
    if (!work) {
        PyErr_NoMemory();
        goto done;
    }
    double amplification = 0.0, residual = NAN;
    {
        double *x = vx.buf, *p = work;
        const double *Gd = vG.buf, *src = vs.buf;
        for (Py_ssize_t m = 0; m < nmills; m++) {
            ch[m].Y = p;
            p += ch[m].n * N;
        }
        double *consts = p, *pred = consts + total, *W = pred + N * S, *y = W + maxn * N, *z = y + N;
        double *A = z + N;
        Py_ssize_t *piv = (Py_ssize_t *)(work + nwork);
        Py_BEGIN_ALLOW_THREADS
        memcpy(A, vA.buf, (size_t)(N * S * S) * sizeof(double));
        double smallest = INFINITY;
        for (Py_ssize_t k = 0; k < N && smallest > 0.0; k++) { /* nothing is solved on a trapped loop */
            const double sm = lu_small(A + k * S * S, S, piv + k * S);
            if (sm < smallest)
                smallest = sm;
        }
        amplification = 1.0 / smallest;
        if (amplification < INFINITY) {
            circuit_classes(N, S, A, piv, src, x, ch, nmills, consts);
            for (Py_ssize_t k = 0; k < N; k++) /* pred = src + Gd x, then the mills' re-solved outputs */
                for (Py_ssize_t r = 0; r < S; r++) {
                    double acc = src[k * S + r];
                    const double *g = Gd + (k * S + r) * S;
                    for (Py_ssize_t q = 0; q < S; q++)
                        acc += g[q] * x[k * S + q];
                    pred[k * S + r] = acc;
                }
            for (Py_ssize_t m = 0; m < nmills; m++) {
                const chain_t *c = ch + m;
                const int64_t *ins = c->ins.buf;
                for (Py_ssize_t k = 0; k < N; k++) {
                    double u = 0.0;
                    for (Py_ssize_t i = 0; i < c->nins; i++)
                        u += x[k * S + ins[i]];
                    y[k] = u;
                }
                memset(W, 0, (size_t)(c->n * N) * sizeof(double));
                chain_forward(N, c->n, c->M.buf, c->MT.buf, y, W, consts);
                for (Py_ssize_t k = 0; k < N; k++)
                    pred[k * S + c->o] += y[k];
            }
            double big = 0.0, scale = 0.0;
            for (Py_ssize_t q = 0; q < N * S; q++) {
                const double e = fabs(x[q] - pred[q]), f = fabs(src[q]);
                big = (e > big || e != e) ? e : big;
                scale = f > scale ? f : scale;
                if (!(x[q] - x[q] == 0.0))
                    amplification = INFINITY;
            }
            residual = big / (scale > 1e-300 ? scale : 1e-300);
        }
        Py_END_ALLOW_THREADS
    }
    result = Py_BuildValue("(dd)", amplification, residual);
done:
    PyMem_Free(work);
    if (ch) {
        release_chains(ch, nmills);
        PyMem_Free(ch);
    }
    Py_XDECREF(seq);
    if (got > 0) PyBuffer_Release(&vA);
    if (got > 1) PyBuffer_Release(&vG);
    if (got > 2) PyBuffer_Release(&vs);
    if (got > 3) PyBuffer_Release(&vx);
    return result;
}

/* Members a pass of population_chains: one vector register's worth of each quantity per
   class on AVX2 (two), four on SSE2, and the sums of a class for every cell of a block
   stay in L1 (n N MEMBERS doubles: 64 kB at n = 10, N = 100). */
#define MEMBERS 8

/* One block of MEMBERS members (member-minor arrays): sT, fT (N, MEMBERS) rates s = tau S / n
   [cell] and feeds, b (N, N) shared, Q (n, N, MEMBERS) work, pT (N, MEMBERS) out. Row i of
   every cell: p^(c)_i = (p^(c-1)_i + sum_{j<i} b_ij q^(c)_j) / (1 + s_i), q^(c)_i = s_i p^(c)_i,
   p^(-1) = f; the sums over j vectorised across the block's members. */
HOT_LOOP static void chain_block(Py_ssize_t N, Py_ssize_t n, const double *RESTRICT b, const double *RESTRICT sT,
                                 const double *RESTRICT fT, double *RESTRICT Q, double *RESTRICT pT)
{
    for (Py_ssize_t i = 0; i < N; i++) {
        const double *brow = b + i * N, *si = sT + i * MEMBERS;
        double prev[MEMBERS];
        for (int m = 0; m < MEMBERS; m++)
            prev[m] = fT[i * MEMBERS + m];
        for (Py_ssize_t c = 0; c < n; c++) {
            double *Qc = Q + c * N * MEMBERS;
            double a0[MEMBERS] = {0}, a1[MEMBERS] = {0};
            Py_ssize_t j = 0;
            for (; j + 2 <= i; j += 2) { /* two sums in flight: the adds' latency, not their count */
                const double b0 = brow[j], b1 = brow[j + 1];
                const double *q0 = Qc + j * MEMBERS, *q1 = q0 + MEMBERS;
                for (int m = 0; m < MEMBERS; m++) {
                    a0[m] += b0 * q0[m];
                    a1[m] += b1 * q1[m];
                }
            }
            if (j < i) {
                const double b0 = brow[j], *q0 = Qc + j * MEMBERS;
                for (int m = 0; m < MEMBERS; m++)
                    a0[m] += b0 * q0[m];
            }
            for (int m = 0; m < MEMBERS; m++) {
                const double p = (prev[m] + (a0[m] + a1[m])) / (1.0 + si[m]);
                prev[m] = p;
                Qc[i * MEMBERS + m] = si[m] * p;
            }
        }
        for (int m = 0; m < MEMBERS; m++)
            pT[i * MEMBERS + m] = prev[m];
    }
}

PyDoc_STRVAR(population_chains_doc,
"population_chains(s, scale, b, f, out, P, N, n, f_rows) -> None\n\n"
"Products of P chains of n equal well-mixed cells (perfect mixing: n = 1; tanks in\n"
"series: n cells of tau/n) that share the breakage b (N, N): scale * s (P, N) the cell's\n"
"rates tau S / (n d*) of each member, f (f_rows, N) the feed (f_rows 1: shared, or P), out (P, N)\n"
"written. Eq. 3 by forward substitution in every cell, class after class, all cells of a\n"
"class in one pass; members in blocks of 8 whose sums over the coarser classes share\n"
"one read of b's row. Non-finite rates give non-finite products (nothing is raised).");

static PyObject *population_chains(PyObject *self, PyObject *args)
{
    PyObject *os, *ob, *of, *oout;
    Py_ssize_t P, N, n, f_rows;
    double scale;
    if (!PyArg_ParseTuple(args, "OdOOOnnnn", &os, &scale, &ob, &of, &oout, &P, &N, &n, &f_rows))
        return NULL;
    if (P < 0 || N < 1 || n < 1 || (f_rows != 1 && f_rows != P)) {
        PyErr_SetString(PyExc_ValueError, "expected P >= 0 members, N >= 1 classes, n >= 1 cells, f_rows 1 or P");
        return NULL;
    }
    Py_buffer vs, vb, vf, vo;
    if (get_buffer(os, &vs, "s", P * N, "d", 0) < 0)
        return NULL;
    if (get_buffer(ob, &vb, "b", N * N, "d", 0) < 0) {
        PyBuffer_Release(&vs);
        return NULL;
    }
    if (get_buffer(of, &vf, "f", f_rows * N, "d", 0) < 0) {
        PyBuffer_Release(&vs);
        PyBuffer_Release(&vb);
        return NULL;
    }
    if (get_buffer(oout, &vo, "out", P * N, "d", 1) < 0) {
        PyBuffer_Release(&vs);
        PyBuffer_Release(&vb);
        PyBuffer_Release(&vf);
        return NULL;
    }
    /* work: sT, fT, pT (N MEMBERS each), Q (n N MEMBERS) */
    double *work = PyMem_Malloc((size_t)((3 + n) * N * MEMBERS) * sizeof(double));
    if (!work) {
        PyBuffer_Release(&vs);
        PyBuffer_Release(&vb);
        PyBuffer_Release(&vf);
        PyBuffer_Release(&vo);
        return PyErr_NoMemory();
    }
    const double *s = vs.buf, *b = vb.buf, *f = vf.buf;
    double *out = vo.buf, *sT = work, *fT = sT + N * MEMBERS, *pT = fT + N * MEMBERS, *Q = pT + N * MEMBERS;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t p0 = 0; p0 < P; p0 += MEMBERS) {
        const Py_ssize_t nb = P - p0 < MEMBERS ? P - p0 : MEMBERS;
        for (Py_ssize_t m = 0; m < MEMBERS; m++) { /* members to member-minor; a short block padded */
            const Py_ssize_t src = m < nb ? p0 + m : p0;
            const double *sm = s + src * N, *fm = f + (f_rows == 1 ? 0 : src) * N;
            for (Py_ssize_t i = 0; i < N; i++) {
                sT[i * MEMBERS + m] = scale * sm[i];
                fT[i * MEMBERS + m] = fm[i];
            }
        }
        chain_block(N, n, b, sT, fT, Q, pT);
        for (Py_ssize_t m = 0; m < nb; m++) {
            double *om = out + (p0 + m) * N;
            for (Py_ssize_t i = 0; i < N; i++)
                om[i] = pT[i * MEMBERS + m];
        }
    }
    Py_END_ALLOW_THREADS
    PyMem_Free(work);
    PyBuffer_Release(&vs);
    PyBuffer_Release(&vb);
    PyBuffer_Release(&vf);
    PyBuffer_Release(&vo);
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"tridiagonal_classes", tridiagonal_classes, METH_VARARGS, tridiagonal_classes_doc},
    {"circuit_solve", circuit_solve, METH_VARARGS, circuit_solve_doc},
    {"chain_column_sums", chain_column_sums, METH_VARARGS, chain_column_sums_doc},
    {"population_chains", population_chains, METH_VARARGS, population_chains_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cells",
    "Compiled class-by-class solve of a row of well-mixed cells (millflow.mill_cells).", -1, methods,
};

PyMODINIT_FUNC PyInit__cells(void)
{
    PyObject *m = PyModule_Create(&module);
    if (m && PyModule_AddIntConstant(m, "KERNEL_VERSION", KERNEL_VERSION) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
