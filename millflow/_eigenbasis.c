/*
 * Row recurrences of the block eigen-decomposition A = X D X^-1 (millflow.linalg).
 *
 * A = (I - b) diag(S) is lower triangular. Row i of A X = X D reads
 *
 *     x_ij (S_j - S_i) = sum_{j <= k < i} A_ik x_kj            (j a singleton column)
 *
 * and, for the clustered columns (block-diagonal D over clusters of close rates),
 * a small triangular solve per row. The Python loop over rows in millflow.linalg
 * costs two numpy calls a row; these loops are the same arithmetic without them.
 * millflow.linalg keeps the numpy versions as the reference and the fallback, and
 * uses this module only when it was compiled (optional build, see setup.py).
 *
 * Arrays come through the buffer protocol (C-contiguous float64 / int64); no numpy
 * headers are needed to build. The GIL is released while computing.
 */
#include "_buffer.h"

/* Bump when the interface or the arithmetic changes: an editable install does not
   rebuild this module by itself, and millflow.linalg ignores a build of another version. */
#define KERNEL_VERSION 1

#if defined(_MSC_VER)
#define RESTRICT __restrict /* MSVC's C mode before /std:c11 has no restrict */
#else
#define RESTRICT restrict
#endif

/* gcc >= 11 (ISA level names) on x86-64 Linux: one copy of the hot loop for AVX2+FMA
   machines, chosen at load time (ifunc), and the baseline copy for the rest; other
   compilers: the baseline only. */
#if defined(__GNUC__) && __GNUC__ >= 11 && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#define HOT_LOOP __attribute__((target_clones("arch=x86-64-v3", "default")))
#else
#define HOT_LOOP
#endif

/* r[0:i] = A[i, 0:i] X[0:i, 0:i] for lower-triangular X (row-major, n columns,
   zeros above the diagonal). Four rows of X per pass: r is loaded and stored once
   for four multiply-adds. */
HOT_LOOP static void row_times_basis(const double *RESTRICT A, const double *RESTRICT X, Py_ssize_t n,
                                     Py_ssize_t i, double *RESTRICT r)
{
    const double *a = A + i * n;
    for (Py_ssize_t j = 0; j < i; j++)
        r[j] = 0.0;
    Py_ssize_t k = 0;
    for (; k + 3 < i; k += 4) {
        const double a0 = a[k], a1 = a[k + 1], a2 = a[k + 2], a3 = a[k + 3];
        const double *x0 = X + k * n, *x1 = x0 + n, *x2 = x1 + n, *x3 = x2 + n;
        for (Py_ssize_t j = 0; j <= k + 3; j++) /* x_kj = 0 for j > k */
            r[j] += a0 * x0[j] + a1 * x1[j] + a2 * x2[j] + a3 * x3[j];
    }
    for (; k < i; k++) {
        const double aik = a[k];
        const double *xk = X + k * n;
        for (Py_ssize_t j = 0; j <= k; j++)
            r[j] += aik * xk[j];
    }
}

PyDoc_STRVAR(distinct_doc,
"distinct(A, S, X)\n\n"
"Unit lower-triangular eigenvectors of A for well separated rates, in place:\n"
"X (n, n) must hold the identity; row i gets x_ij = (A_i,<i X_<i,j) / (S_j - S_i).");

static PyObject *distinct(PyObject *self, PyObject *args)
{
    PyObject *oA, *oS, *oX;
    if (!PyArg_ParseTuple(args, "OOO", &oA, &oS, &oX))
        return NULL;
    Py_buffer vS, vA, vX;
    if (get_buffer(oS, &vS, "S", -1, "d", 0) < 0)
        return NULL;
    Py_ssize_t n = vS.len / (Py_ssize_t)sizeof(double);
    if (get_buffer(oA, &vA, "A", n * n, "d", 0) < 0) {
        PyBuffer_Release(&vS);
        return NULL;
    }
    if (get_buffer(oX, &vX, "X", n * n, "d", 1) < 0) {
        PyBuffer_Release(&vS);
        PyBuffer_Release(&vA);
        return NULL;
    }
    double *r = PyMem_Malloc((size_t)(n > 0 ? n : 1) * sizeof(double));
    if (!r) {
        PyBuffer_Release(&vS);
        PyBuffer_Release(&vA);
        PyBuffer_Release(&vX);
        return PyErr_NoMemory();
    }
    const double *A = vA.buf, *S = vS.buf;
    double *X = vX.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 1; i < n; i++) {
        row_times_basis(A, X, n, i, r);
        double *xi = X + i * n;
        const double si = S[i];
        for (Py_ssize_t j = 0; j < i; j++)
            xi[j] = r[j] / (S[j] - si);
    }
    Py_END_ALLOW_THREADS
    PyMem_Free(r);
    PyBuffer_Release(&vS);
    PyBuffer_Release(&vA);
    PyBuffer_Release(&vX);
    Py_RETURN_NONE;
}

PyDoc_STRVAR(clustered_doc,
"clustered(A, S, X, cc, label, D)\n\n"
"Basis X and block-diagonal D over the clustered classes, in place.\n"
"X (n, n) must hold the identity; cc (k,) int64 are the clustered classes in index\n"
"order, label (n,) int64 their cluster labels, D (k, k) must hold diag(S[cc]).\n"
"Row i: r = A_i,<i X_<i. Singleton columns: x_ij = r_j / (S_j - S_i). Clustered\n"
"columns of other clusters: y (D_C - S_i I) = r_C by back substitution. A clustered\n"
"row's own cluster: D_i,C = r_C and x_i,C = 0.");

static PyObject *clustered(PyObject *self, PyObject *args)
{
    PyObject *oA, *oS, *oX, *occ, *olab, *oD;
    if (!PyArg_ParseTuple(args, "OOOOOO", &oA, &oS, &oX, &occ, &olab, &oD))
        return NULL;
    Py_buffer vS, vA, vX, vcc, vlab, vD;
    int got = 0;
    if (get_buffer(oS, &vS, "S", -1, "d", 0) < 0) goto fail;
    got = 1;
    const Py_ssize_t n = vS.len / (Py_ssize_t)sizeof(double);
    if (get_buffer(oA, &vA, "A", n * n, "d", 0) < 0) goto fail;
    got = 2;
    if (get_buffer(oX, &vX, "X", n * n, "d", 1) < 0) goto fail;
    got = 3;
    if (get_buffer(occ, &vcc, "cc", -1, "q", 0) < 0) goto fail;
    got = 4;
    const Py_ssize_t kc = vcc.len / 8;
    if (get_buffer(olab, &vlab, "label", n, "q", 0) < 0) goto fail;
    got = 5;
    if (get_buffer(oD, &vD, "D", kc * kc, "d", 1) < 0) goto fail;
    got = 6;

    const double *A = vA.buf, *S = vS.buf;
    double *X = vX.buf, *D = vD.buf;
    const int64_t *cc = vcc.buf, *label = vlab.buf;
    for (Py_ssize_t p = 0; p < kc; p++) {
        if (cc[p] < 0 || cc[p] >= n || (p > 0 && cc[p] <= cc[p - 1])) {
            PyErr_SetString(PyExc_ValueError, "cc: expected increasing class indices in [0, n)");
            goto fail;
        }
    }
    /* workspace: r (n), y (kc), is_clustered (n) */
    double *r = PyMem_Malloc((size_t)(n + kc + 1) * sizeof(double));
    char *is_cl = PyMem_Malloc((size_t)(n + 1));
    Py_ssize_t *pos = PyMem_Malloc((size_t)(n + 1) * sizeof(Py_ssize_t));
    if (!r || !is_cl || !pos) {
        PyMem_Free(r);
        PyMem_Free(is_cl);
        PyMem_Free(pos);
        PyErr_NoMemory();
        goto fail;
    }
    double *y = r + n;
    Py_BEGIN_ALLOW_THREADS
    memset(is_cl, 0, (size_t)n);
    for (Py_ssize_t p = 0; p < kc; p++) {
        is_cl[cc[p]] = 1;
        pos[cc[p]] = p;
    }
    Py_ssize_t k = 0; /* clustered classes before row i */
    for (Py_ssize_t i = 1; i < n; i++) {
        while (k < kc && cc[k] < i)
            k++;
        row_times_basis(A, X, n, i, r);
        double *xi = X + i * n;
        const double si = S[i];
        for (Py_ssize_t j = 0; j < i; j++)
            xi[j] = is_cl[j] ? 0.0 : r[j] / (S[j] - si);
        if (!k)
            continue;
        const int64_t own = is_cl[i] ? label[i] : -1;
        if (own >= 0) {
            double *drow = D + pos[i] * kc;
            for (Py_ssize_t p = 0; p < k; p++)
                if (label[cc[p]] == own)
                    drow[p] = r[cc[p]];
        }
        /* y (D_C - S_i I) = r_C for every other cluster C: back substitution, since
           (D_C - S_i I)^T is upper triangular; D is zero between different clusters */
        for (Py_ssize_t p = k - 1; p >= 0; p--) {
            const int64_t lp = label[cc[p]];
            if (lp == own) {
                y[p] = 0.0;
                continue;
            }
            double acc = r[cc[p]];
            for (Py_ssize_t q = p + 1; q < k; q++) {
                const double dqp = D[q * kc + p];
                if (dqp != 0.0)
                    acc -= y[q] * dqp;
            }
            y[p] = acc / (D[p * kc + p] - si);
            xi[cc[p]] = y[p];
        }
    }
    Py_END_ALLOW_THREADS
    PyMem_Free(r);
    PyMem_Free(is_cl);
    PyMem_Free(pos);
    PyBuffer_Release(&vS);
    PyBuffer_Release(&vA);
    PyBuffer_Release(&vX);
    PyBuffer_Release(&vcc);
    PyBuffer_Release(&vlab);
    PyBuffer_Release(&vD);
    Py_RETURN_NONE;

fail:
    if (got > 0) PyBuffer_Release(&vS);
    if (got > 1) PyBuffer_Release(&vA);
    if (got > 2) PyBuffer_Release(&vX);
    if (got > 3) PyBuffer_Release(&vcc);
    if (got > 4) PyBuffer_Release(&vlab);
    if (got > 5) PyBuffer_Release(&vD);
    return NULL;
}

static PyMethodDef methods[] = {
    {"distinct", distinct, METH_VARARGS, distinct_doc},
    {"clustered", clustered, METH_VARARGS, clustered_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_eigenbasis",
    "Compiled row recurrences of millflow.linalg's block eigen-decomposition.", -1, methods,
};

PyMODINIT_FUNC PyInit__eigenbasis(void)
{
    PyObject *m = PyModule_Create(&module);
    if (m && PyModule_AddIntConstant(m, "KERNEL_VERSION", KERNEL_VERSION) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
