/* The fully overlapping Allan variance's inner loop in C: avard.core.allan._kernels.
 *
 * numpy needs three element-wise passes and a dot product to sum the second differences
 * D_i = X_{i+2m} - 2 X_{i+m} + X_i of the phase (NIST SP 1065 eq. 12), each pass writing a
 * temporary; this loop reads the three spans once and keeps D in registers (measured 1.3 ns
 * against 0.37 ns per sample and tau in the cache). It is a fast path beside the numpy one
 * in avard.core.allan.kernels, which a test holds equal to it; the build is optional
 * (setup.py), so avard runs without a compiler.
 *
 * Functions (float64, 1-D, C-contiguous buffers of one channel, equal lengths n):
 *   sumsq(x0, x1, x2) -> float
 *       sum_i D_i^2 with D_i = (x2[i] - x1[i]) - (x1[i] - x0[i]).
 *   sumsq_mod(x0, x1, x2, ring, k, last) -> (sum D^2, sum w^2, count of w, new last)
 *       also the modified AVAR's sums (SP 1065 eq. 14) as RnSums keeps them: P the running
 *       sum of D over the segment (P_0 = 0, P_k = last after the k differences seen so far),
 *       ring[j mod m] holding P_j for the last m indices j (m = len(ring)); every new index
 *       e = k+1 ... k+n with e >= m gives w = P_e - P_{e-m}, summed as w^2.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

static int
get_vector(PyObject *obj, Py_buffer *view, int writable, const char *name)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) < 0)
        return -1;
    if (view->ndim != 1 || view->itemsize != 8 || view->format == NULL
            || strcmp(view->format, "d") != 0) {
        PyErr_Format(PyExc_TypeError, "%s must be a 1-D contiguous float64 array", name);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

static int
get_spans(PyObject *const *args, Py_buffer views[3])
{
    static const char *names[3] = {"x0", "x1", "x2"};
    for (int j = 0; j < 3; j++) {
        if (get_vector(args[j], &views[j], 0, names[j]) < 0) {
            for (int i = 0; i < j; i++)
                PyBuffer_Release(&views[i]);
            return -1;
        }
    }
    if (views[0].shape[0] != views[1].shape[0] || views[0].shape[0] != views[2].shape[0]) {
        PyErr_SetString(PyExc_ValueError, "x0, x1 and x2 must have the same length");
        for (int i = 0; i < 3; i++)
            PyBuffer_Release(&views[i]);
        return -1;
    }
    return 0;
}

/* Four partial sums: independent chains the compiler can keep in vector registers, and a
 * rounding error closer to a pairwise sum's than one long chain's. */
static double
sumsq_loop(const double *x0, const double *x1, const double *x2, Py_ssize_t n)
{
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    Py_ssize_t i = 0;
    for (; i + 4 <= n; i += 4) {
        double d0 = (x2[i] - x1[i]) - (x1[i] - x0[i]);
        double d1 = (x2[i + 1] - x1[i + 1]) - (x1[i + 1] - x0[i + 1]);
        double d2 = (x2[i + 2] - x1[i + 2]) - (x1[i + 2] - x0[i + 2]);
        double d3 = (x2[i + 3] - x1[i + 3]) - (x1[i + 3] - x0[i + 3]);
        s0 += d0 * d0;
        s1 += d1 * d1;
        s2 += d2 * d2;
        s3 += d3 * d3;
    }
    for (; i < n; i++) {
        double d = (x2[i] - x1[i]) - (x1[i] - x0[i]);
        s0 += d * d;
    }
    return (s0 + s1) + (s2 + s3);
}

static PyObject *
kernels_sumsq(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    Py_buffer v[3];
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "sumsq(x0, x1, x2) takes 3 arrays");
        return NULL;
    }
    if (get_spans(args, v) < 0)
        return NULL;
    double s;
    Py_BEGIN_ALLOW_THREADS
    s = sumsq_loop(v[0].buf, v[1].buf, v[2].buf, v[0].shape[0]);
    Py_END_ALLOW_THREADS
    for (int i = 0; i < 3; i++)
        PyBuffer_Release(&v[i]);
    return PyFloat_FromDouble(s);
}

static PyObject *
kernels_sumsq_mod(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    Py_buffer v[3], r;
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "sumsq_mod(x0, x1, x2, ring, k, last) takes 6 arguments");
        return NULL;
    }
    long long k = PyLong_AsLongLong(args[4]);
    if (k == -1 && PyErr_Occurred())
        return NULL;
    double last = PyFloat_AsDouble(args[5]);
    if (last == -1.0 && PyErr_Occurred())
        return NULL;
    if (k < 0) {
        PyErr_SetString(PyExc_ValueError, "k must be >= 0");
        return NULL;
    }
    if (get_spans(args, v) < 0)
        return NULL;
    if (get_vector(args[3], &r, 1, "ring") < 0) {
        for (int i = 0; i < 3; i++)
            PyBuffer_Release(&v[i]);
        return NULL;
    }
    const Py_ssize_t m = r.shape[0];
    if (m < 1) {
        PyErr_SetString(PyExc_ValueError, "ring must hold at least one value");
        for (int i = 0; i < 3; i++)
            PyBuffer_Release(&v[i]);
        PyBuffer_Release(&r);
        return NULL;
    }
    const double *x0 = v[0].buf, *x1 = v[1].buf, *x2 = v[2].buf;
    double *ring = r.buf;
    const Py_ssize_t n = v[0].shape[0];
    double s_d = 0.0, s_mod = 0.0, p = last;
    /* sum D^2 in the partial sums and order of sumsq_loop, so that the two give the very
     * same bits (the OADEV must not change with whether R(n) is kept) */
    double part[4] = {0.0, 0.0, 0.0, 0.0};
    const Py_ssize_t n4 = n - n % 4;
    long long n_mod = 0;
    Py_BEGIN_ALLOW_THREADS
    long long e = k;
    Py_ssize_t slot = (Py_ssize_t)(k % m);
    for (Py_ssize_t i = 0; i < n; i++) {
        double d = (x2[i] - x1[i]) - (x1[i] - x0[i]);
        part[i < n4 ? (i & 3) : 0] += d * d;
        p += d;
        e += 1;
        slot = slot + 1 == m ? 0 : slot + 1;  /* e mod m */
        if (e >= m) {
            double w = p - ring[slot];  /* ring[e mod m] still holds P_{e-m} */
            s_mod += w * w;
            n_mod += 1;
        }
        ring[slot] = p;
    }
    s_d = (part[0] + part[1]) + (part[2] + part[3]);
    Py_END_ALLOW_THREADS
    for (int i = 0; i < 3; i++)
        PyBuffer_Release(&v[i]);
    PyBuffer_Release(&r);
    return Py_BuildValue("(ddLd)", s_d, s_mod, n_mod, p);
}

static PyMethodDef kernels_methods[] = {
    {"sumsq", (PyCFunction)(void (*)(void))kernels_sumsq, METH_FASTCALL,
     "sumsq(x0, x1, x2): sum of ((x2 - x1) - (x1 - x0))**2 over float64 vectors"},
    {"sumsq_mod", (PyCFunction)(void (*)(void))kernels_sumsq_mod, METH_FASTCALL,
     "sumsq_mod(x0, x1, x2, ring, k, last): sumsq and the modified AVAR's running sums"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef kernels_module = {
    PyModuleDef_HEAD_INIT, "_kernels",
    "Compiled inner loops of the fully overlapping Allan variance (optional).", -1,
    kernels_methods, NULL, NULL, NULL, NULL,
};

/* The interface version avard.core.allan.kernels expects (its API): raise both together. */
#define KERNELS_API 1

PyMODINIT_FUNC
PyInit__kernels(void)
{
    PyObject *mod = PyModule_Create(&kernels_module);
    if (mod != NULL && PyModule_AddIntConstant(mod, "API", KERNELS_API) < 0) {
        Py_DECREF(mod);
        return NULL;
    }
    return mod;
}
