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
 * optional build (setup.py). Arrays come through the buffer protocol (C-contiguous
 * float64); the GIL is released while computing.
 */
#include "_buffer.h"

/* Bump when the interface or the arithmetic changes (see millflow/_eigenbasis.c). */
#define KERNEL_VERSION 1

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

static PyMethodDef methods[] = {
    {"tridiagonal_classes", tridiagonal_classes, METH_VARARGS, tridiagonal_classes_doc},
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
