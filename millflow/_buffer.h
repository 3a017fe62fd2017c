/*
 * Buffers for millflow's optional C kernels (_eigenbasis.c, _cells.c): arrays arrive
 * through the buffer protocol, checked for type, size and C order here.
 */
#ifndef MILLFLOW_BUFFER_H
#define MILLFLOW_BUFFER_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <string.h>

/* Get a C-contiguous buffer of `n` items (any number if n < 0) of format `fmt`
   ("d" float64 or "q" int64). */
static int get_buffer(PyObject *obj, Py_buffer *view, const char *name, Py_ssize_t n,
                      const char *fmt, int writable)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) < 0)
        return -1;
    Py_ssize_t itemsize = (fmt[0] == 'd') ? (Py_ssize_t)sizeof(double) : (Py_ssize_t)sizeof(int64_t);
    const char *f = view->format ? view->format : "B";
    if (f[0] == '<' || f[0] == '=' || f[0] == '@')
        f++;
    int ok_format = (fmt[0] == 'd') ? (strcmp(f, "d") == 0)
                                    : ((strcmp(f, "q") == 0 || strcmp(f, "l") == 0) && view->itemsize == 8);
    if (!ok_format || view->itemsize != itemsize || (n >= 0 && view->len != n * itemsize)) {
        if (n >= 0)
            PyErr_Format(PyExc_ValueError, "%s: expected %zd C-contiguous %s items", name, n,
                         fmt[0] == 'd' ? "float64" : "int64");
        else
            PyErr_Format(PyExc_ValueError, "%s: expected C-contiguous %s items", name,
                         fmt[0] == 'd' ? "float64" : "int64");
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

#endif
