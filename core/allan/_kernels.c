/* analyze's inner loops in C: avard.core.allan._kernels.
 *
 * numpy needs three element-wise passes and a dot product to sum the second differences
 * D_i = X_{i+2m} - 2 X_{i+m} + X_i of the phase (NIST SP 1065 eq. 12), each pass writing a
 * temporary; sumsq reads the three spans once and keeps D in registers (measured 1.3 ns
 * against 0.37 ns per sample and tau in the cache). The running sum, the noise
 * identification's sums and the Welch power sum are here for the same reason (see each).
 * Every loop is a fast path beside a numpy one in avard.core.allan.kernels and its callers,
 * which tests hold equal to it; the build is optional (setup.py), so avard runs without a
 * compiler.
 *
 * Functions (float64, 1-D, C-contiguous buffers of one channel unless said, equal lengths n):
 *   sumsq(x0, x1, x2) -> float
 *       sum_i D_i^2 with D_i = (x2[i] - x1[i]) - (x1[i] - x0[i]).
 *   sumsq_ring(ring, spans, out)
 *       sumsq for many tau of every channel in one call: ring (C, cap) C-contiguous, the
 *       OADEV's running-sum history, whose segment position p sits at ring[c, p mod cap];
 *       spans (K, 3) int64 rows (lo, m, n); out (K, C): out[k, c] = sumsq of channel c's
 *       spans at positions lo .. lo+n-1, lo+m .., lo+2m .. (in order across the ring's
 *       end where a span wraps), bit for bit what sumsq gives on copies of those spans.
 *       One call per piece instead of one per tau and channel, and no copy of a wrapped
 *       span (fresh memory, page-faulted on every copy): both cost the OADEV more than
 *       the sums of those spans themselves.
 *   sumsq_mod(x0, x1, x2, ring, k, last) -> (sum D^2, sum w^2, count of w, new last)
 *       also the modified AVAR's sums (SP 1065 eq. 14) as RnSums keeps them: P the running
 *       sum of D over the segment (P_0 = 0, P_k = last after the k differences seen so far),
 *       ring[j mod m] holding P_j for the last m indices j (m = len(ring)); every new index
 *       e = k+1 ... k+n with e >= m gives w = P_e - P_{e-m}, summed as w^2.
 *   running_sum(y, offset, carry, out) -> the last value
 *       out[i] = carry + sum_{j <= i} (y[j] - offset), added left to right as numpy's cumsum
 *       adds (the same bits); y may be strided (a column of a block of samples), so the
 *       transposing copy, the offset and the running sum are one pass (numpy's cumsum alone
 *       measured 3.4 ns per value).
 *   power_sum(spec, k, out)
 *       the Welch spectrum's accumulation: spec a float64 view of k blocks of complex
 *       transforms (re, im pairs), each block as long as out; out[j] += sum over the blocks
 *       of re^2 + im^2 of its j-th value (numpy's square, sum over the blocks and sum over
 *       the pairs: three passes over the transforms, measured 0.7 ms against 0.1 ms per
 *       eight 16384-point segments of two channels).
 *   lag_sums(x, m, ref, out, old) -> number of values
 *       the noise identification's sums over one channel's averages z (Lag1Ladder): with
 *       m >= 1, z_j = (x[(j+1)m] - x[jm]) - ref for j = 0 ... (len(x) - 1)/m - 1 (x a span of
 *       the running sum, z the non-overlapping sums of m samples, never stored); with m = 0,
 *       z_j = x[j] - ref. The first `old` values (at most LAG_MAX) were pushed before: they
 *       enter only the products that reach a new value. Adds sum z over the new values to
 *       out[0] and sum z_t z_{t+j} over pairs whose later value is new to out[1 + j], for the
 *       lags j = 0 ... len(out) - 2 (at most LAG_MAX = 3, what the ladder's dmax = 2 needs).
 *   local_residual(y, half, out)
 *       the input screen's high-pass statistic (avard.core.io.screen): out[i] = |x_i - the
 *       mean of x over i - half ... i + half| with x = y - y[0], the window reflected at the
 *       ends as numpy's pad(mode="reflect") does (x_{-j} = x_j, x_{n-1+j} = x_{n-1-j}); y
 *       may be strided (a column of a block), n > 2 half. One pass with a moving window sum
 *       where numpy pads, sums cumulatively and subtracts (five passes and two temporaries).
 *   first_order(x, b0, b1, a1, z, out) -> the last state
 *       y_i = z + b0 x_i, then z = b1 x_i - a1 y_i, from the state z given: scipy.signal's
 *       lfilter([b0, b1], [1, a1], x, zi=[z]) (direct form II transposed), the same
 *       operations in the same order. avard explain's thermal lag (thermal_fit.lag_filter)
 *       filters the slow view with it, so explain need not import scipy.signal (and with
 *       it scipy.stats), which cost more CPU than all its filtering.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

/* A 1-D float64 buffer: C-contiguous, or with ``strided`` any whole-element stride (a column
 * of a block); writable for an output. */
static int
get_vector_as(PyObject *obj, Py_buffer *view, int writable, int strided, const char *name)
{
    int flags = (strided ? PyBUF_STRIDES : PyBUF_C_CONTIGUOUS) | PyBUF_FORMAT
                | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) < 0)
        return -1;
    if (view->ndim != 1 || view->itemsize != 8 || view->format == NULL
            || strcmp(view->format, "d") != 0 || (strided && view->strides[0] % 8 != 0)) {
        PyErr_Format(PyExc_TypeError, strided ? "%s must be a 1-D float64 array"
                     : "%s must be a 1-D contiguous float64 array", name);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

static int
get_vector(PyObject *obj, Py_buffer *view, int writable, const char *name)
{
    return get_vector_as(obj, view, writable, 0, name);
}

/* An input vector (strided if asked) and a contiguous writable output, both or neither. */
static int
get_in_out(PyObject *in, PyObject *out, Py_buffer *vin, Py_buffer *vout, int strided,
           const char *in_name)
{
    if (get_vector_as(in, vin, 0, strided, in_name) < 0)
        return -1;
    if (get_vector(out, vout, 1, "out") < 0) {
        PyBuffer_Release(vin);
        return -1;
    }
    return 0;
}

/* Release both and return NULL: a refusal after get_in_out, its error already set. */
static PyObject *
release2(Py_buffer *a, Py_buffer *b)
{
    PyBuffer_Release(a);
    PyBuffer_Release(b);
    return NULL;
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

/* x86-64 with GCC and glibc: an AVX2 copy of sumsq's loop beside the baseline one, the loader
 * picking it where the CPU has AVX2 (the four partial sums then sit in one 256-bit register,
 * not two 128-bit ones: about a sixth less time for the OADEV's largest cost). The same
 * operations in the same order, so the same bits: AVX2 alone brings no FMA that could fuse
 * d*d into the sum (tests/core/test_kernels.py holds sumsq equal to sumsq_mod's own loop). */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__GLIBC__)
#define SUMSQ_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define SUMSQ_CLONES
#endif

/* Four partial sums: independent chains the compiler can keep in vector registers, and a
 * rounding error closer to a pairwise sum's than one long chain's. */
__attribute__((noinline)) SUMSQ_CLONES static double
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

/* sumsq of the spans of n ring points from ring indices a, b, c (each < cap) of one channel's
 * ring row. Where no span wraps round the ring's end, sumsq_loop on views of it; where one
 * does, the same sums run by run between the wrap points, each lane taking the differences
 * sumsq_loop gives it (i mod 4 before the last n mod 4, lane 0 for those) in the same order:
 * the very bits, with no copy (a gathered copy of fresh memory cost page faults per call). */
static double
sumsq_ring_span(const double *row, Py_ssize_t cap, Py_ssize_t a, Py_ssize_t b, Py_ssize_t c,
                Py_ssize_t n)
{
    if (a + n <= cap && b + n <= cap && c + n <= cap)
        return sumsq_loop(row + a, row + b, row + c, n);
    double s[4] = {0.0, 0.0, 0.0, 0.0};
    const Py_ssize_t n4 = n - n % 4;
    Py_ssize_t i = 0;
    while (i < n) {
        Py_ssize_t ia = (a + i) % cap, ib = (b + i) % cap, ic = (c + i) % cap;
        Py_ssize_t run = n - i;
        if (cap - ia < run)
            run = cap - ia;
        if (cap - ib < run)
            run = cap - ib;
        if (cap - ic < run)
            run = cap - ic;
        const double *x0 = row + ia, *x1 = row + ib, *x2 = row + ic;
        for (Py_ssize_t j = 0; j < run; j++, i++) {
            double d = (x2[j] - x1[j]) - (x1[j] - x0[j]);
            s[i < n4 ? (i & 3) : 0] += d * d;
        }
    }
    return (s[0] + s[1]) + (s[2] + s[3]);
}

static PyObject *
kernels_sumsq_ring(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    Py_buffer r, sp, o;
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "sumsq_ring(ring, spans, out) takes 3 arrays");
        return NULL;
    }
    if (PyObject_GetBuffer(args[0], &r, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return NULL;
    if (PyObject_GetBuffer(args[1], &sp, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0) {
        PyBuffer_Release(&r);
        return NULL;
    }
    if (PyObject_GetBuffer(args[2], &o, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | PyBUF_WRITABLE) < 0) {
        PyBuffer_Release(&r);
        PyBuffer_Release(&sp);
        return NULL;
    }
    PyObject *result = NULL;
    if (r.ndim != 2 || r.itemsize != 8 || strcmp(r.format, "d") != 0
            || o.ndim != 2 || o.itemsize != 8 || strcmp(o.format, "d") != 0
            || sp.ndim != 2 || sp.itemsize != 8 || (strcmp(sp.format, "l") != 0
                                                    && strcmp(sp.format, "q") != 0)) {
        PyErr_SetString(PyExc_TypeError, "ring and out must be 2-D contiguous float64 arrays, "
                        "spans a 2-D contiguous int64 array");
        goto done;
    }
    const Py_ssize_t c = r.shape[0], cap = r.shape[1], k = sp.shape[0];
    if (sp.shape[1] != 3 || o.shape[0] != k || o.shape[1] != c || cap < 1) {
        PyErr_SetString(PyExc_ValueError, "spans must be (K, 3) rows (lo, m, n) and out (K, C) "
                        "for a ring of C channels");
        goto done;
    }
    const long long *rows = sp.buf;
    for (Py_ssize_t j = 0; j < k; j++) {
        const long long lo = rows[3 * j], m = rows[3 * j + 1], n = rows[3 * j + 2];
        if (lo < 0 || m < 1 || n < 0 || n > cap) {
            PyErr_SetString(PyExc_ValueError, "a span needs lo >= 0, m >= 1 and 0 <= n <= cap");
            goto done;
        }
    }
    const double *ring = r.buf;
    double *out = o.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t j = 0; j < k; j++) {
        const long long lo = rows[3 * j], m = rows[3 * j + 1];
        const Py_ssize_t n = (Py_ssize_t)rows[3 * j + 2];
        const Py_ssize_t a = (Py_ssize_t)(lo % cap), b = (Py_ssize_t)((lo + m) % cap),
                         c2 = (Py_ssize_t)((lo + 2 * m) % cap);
        for (Py_ssize_t ch = 0; ch < c; ch++)
            out[j * c + ch] = sumsq_ring_span(ring + ch * cap, cap, a, b, c2, n);
    }
    Py_END_ALLOW_THREADS
    result = Py_None;
    Py_INCREF(result);
done:
    PyBuffer_Release(&r);
    PyBuffer_Release(&sp);
    PyBuffer_Release(&o);
    return result;
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

/* lag_sums: the averages are made a block at a time into a buffer in the L1 cache (with the
 * next few values, and zeros past the last, so that every product of the block is there),
 * then one loop carries the sum and the four lag products on pairs of values in vector
 * registers (GCC's vector extension: SSE2 on x86-64, NEON on a Pi's aarch64), two
 * accumulators per sum so that no sum waits on its own adds. Measured 0.55 ns per value
 * against 1.1 for a separate loop per sum and 1.3 for numpy's sum and four dot products,
 * before its passes making the averages. */
#define LAG_MAX 3
#define LAG_BLOCK 512

typedef double v2d __attribute__((vector_size(16)));

static inline v2d
load2(const double *p)
{
    v2d v;
    memcpy(&v, p, sizeof v);  /* unaligned: buf + j for odd j */
    return v;
}

static void
lag_loop(const double *x, Py_ssize_t m, Py_ssize_t k, double ref, int lags, int old,
         double *out)
{
    double buf[LAG_BLOCK + 8];
    v2d acc[5][2];
    double rest[5] = {0.0, 0.0, 0.0, 0.0, 0.0};
    memset(acc, 0, sizeof acc);
    for (Py_ssize_t t0 = 0; t0 < k; t0 += LAG_BLOCK) {
        Py_ssize_t nb = k - t0 < LAG_BLOCK ? k - t0 : LAG_BLOCK;  /* this block's values */
        Py_ssize_t ne = k - t0 < nb + LAG_MAX ? k - t0 : nb + LAG_MAX;  /* and the next few */
        if (m == 0) {
            const double *z = x + t0;
            for (Py_ssize_t i = 0; i < ne; i++)
                buf[i] = z[i] - ref;
        } else if (m == 1) {
            const double *p = x + t0;
            for (Py_ssize_t i = 0; i < ne; i++)
                buf[i] = (p[i + 1] - p[i]) - ref;
        } else {
            const double *p = x + t0 * m;
            for (Py_ssize_t i = 0; i < ne; i++)
                buf[i] = (p[(i + 1) * m] - p[i * m]) - ref;
        }
        for (Py_ssize_t i = ne; i < nb + 8; i++)
            buf[i] = 0.0;  /* past the last value: its products are 0 */
        Py_ssize_t i = 0;
        for (; i + 4 <= nb; i += 4) {
            v2d a = load2(buf + i), b = load2(buf + i + 2);
            acc[0][0] += a;
            acc[0][1] += b;
            acc[1][0] += a * a;
            acc[1][1] += b * b;
            acc[2][0] += a * load2(buf + i + 1);
            acc[2][1] += b * load2(buf + i + 3);
            acc[3][0] += a * load2(buf + i + 2);
            acc[3][1] += b * load2(buf + i + 4);
            acc[4][0] += a * load2(buf + i + 3);
            acc[4][1] += b * load2(buf + i + 5);
        }
        for (; i < nb; i++) {
            double z = buf[i];
            rest[0] += z;
            for (int j = 0; j <= LAG_MAX; j++)
                rest[1 + j] += z * buf[i + j];
        }
    }
    /* less the sums among the old values alone (pushed before with their own products) */
    double z[LAG_MAX];
    for (int i = 0; i < old; i++)
        z[i] = (m == 0 ? x[i] : x[(i + 1) * m] - x[i * m]) - ref;
    for (int i = 0; i < old; i++) {
        rest[0] -= z[i];
        for (int j = 0; i + j < old; j++)
            rest[1 + j] -= z[i] * z[i + j];
    }
    for (int j = 0; j < lags + 2; j++) {
        v2d v = acc[j][0] + acc[j][1];
        out[j] += (v[0] + v[1]) + rest[j];
    }
}

static PyObject *
kernels_lag_sums(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    Py_buffer v, o;
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "lag_sums(x, m, ref, out, old) takes 5 arguments");
        return NULL;
    }
    long old = PyLong_AsLong(args[4]);
    if (old == -1 && PyErr_Occurred())
        return NULL;
    Py_ssize_t m = PyLong_AsSsize_t(args[1]);
    if (m == -1 && PyErr_Occurred())
        return NULL;
    double ref = PyFloat_AsDouble(args[2]);
    if (ref == -1.0 && PyErr_Occurred())
        return NULL;
    if (m < 0) {
        PyErr_SetString(PyExc_ValueError, "m must be >= 0");
        return NULL;
    }
    if (get_in_out(args[0], args[3], &v, &o, 0, "x") < 0)
        return NULL;
    Py_ssize_t lags = o.shape[0] - 2;
    if (lags < 0 || lags > LAG_MAX) {
        PyErr_Format(PyExc_ValueError, "out must hold 2 to %d values", LAG_MAX + 2);
        return release2(&v, &o);
    }
    Py_ssize_t n = v.shape[0];
    Py_ssize_t k = m == 0 ? n : (n > 0 ? (n - 1) / m : 0);
    if (old < 0 || old > LAG_MAX || old > k) {
        PyErr_Format(PyExc_ValueError, "old must be 0 to %d and at most the values in x",
                     LAG_MAX);
        return release2(&v, &o);
    }
    Py_BEGIN_ALLOW_THREADS
    lag_loop(v.buf, m, k, ref, (int)lags, (int)old, o.buf);
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&v);
    PyBuffer_Release(&o);
    return PyLong_FromSsize_t(k);
}

static PyObject *
kernels_running_sum(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    Py_buffer y, o;
    if (nargs != 4) {
        PyErr_SetString(PyExc_TypeError, "running_sum(y, offset, carry, out) takes 4 arguments");
        return NULL;
    }
    double offset = PyFloat_AsDouble(args[1]);
    if (offset == -1.0 && PyErr_Occurred())
        return NULL;
    double carry = PyFloat_AsDouble(args[2]);
    if (carry == -1.0 && PyErr_Occurred())
        return NULL;
    if (get_in_out(args[0], args[3], &y, &o, 1, "y") < 0)
        return NULL;
    if (o.shape[0] != y.shape[0]) {
        PyErr_SetString(PyExc_ValueError, "y and out must have the same length");
        return release2(&y, &o);
    }
    const double *src = y.buf;
    const Py_ssize_t step = y.strides[0] / 8, n = y.shape[0];
    double *dst = o.buf, acc = carry;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        acc = acc + (src[i * step] - offset);
        dst[i] = acc;
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&y);
    PyBuffer_Release(&o);
    return PyFloat_FromDouble(acc);
}

static PyObject *
kernels_power_sum(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    Py_buffer v, o;
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "power_sum(spec, k, out) takes 3 arguments");
        return NULL;
    }
    Py_ssize_t k = PyLong_AsSsize_t(args[1]);
    if (k == -1 && PyErr_Occurred())
        return NULL;
    if (get_in_out(args[0], args[2], &v, &o, 0, "spec") < 0)
        return NULL;
    const Py_ssize_t f = o.shape[0];
    if (k < 0 || v.shape[0] != 2 * k * f) {
        PyErr_SetString(PyExc_ValueError, "spec must hold k blocks of len(out) complex values");
        return release2(&v, &o);
    }
    const double *src = v.buf;
    double *dst = o.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t b = 0; b < k; b++) {
        const double *blk = src + 2 * b * f;
        for (Py_ssize_t j = 0; j < f; j++)
            dst[j] += blk[2 * j] * blk[2 * j] + blk[2 * j + 1] * blk[2 * j + 1];
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&v);
    PyBuffer_Release(&o);
    Py_RETURN_NONE;
}

static PyObject *
kernels_local_residual(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    Py_buffer v, o;
    if (nargs != 3) {
        PyErr_SetString(PyExc_TypeError, "local_residual(y, half, out) takes 3 arguments");
        return NULL;
    }
    Py_ssize_t h = PyLong_AsSsize_t(args[1]);
    if (h == -1 && PyErr_Occurred())
        return NULL;
    if (get_in_out(args[0], args[2], &v, &o, 1, "y") < 0)
        return NULL;
    const Py_ssize_t n = v.shape[0];
    if (h < 0 || n <= 2 * h || o.shape[0] != n) {
        PyErr_SetString(PyExc_ValueError, "local_residual needs len(y) > 2 half >= 0 and out "
                        "as long as y");
        return release2(&v, &o);
    }
    const char *base = v.buf;
    const Py_ssize_t stride = v.strides[0];
    double *dst = o.buf;
    Py_BEGIN_ALLOW_THREADS
    const double y0 = *(const double *)base;
#define X(j) (*(const double *)(base + (j) * stride) - y0)
#define REFL(j) ((j) < 0 ? -(j) : ((j) >= n ? 2 * (n - 1) - (j) : (j)))
    const double w = (double)(2 * h + 1);
    double s = 0.0;
    for (Py_ssize_t j = -h; j <= h; j++)
        s += X(REFL(j));
    /* the ends reflect; between them the window moves by one sample without a branch */
    const Py_ssize_t lo = h < n ? h : n, hi = n - h - 1 > lo ? n - h - 1 : lo;
    for (Py_ssize_t i = 0; i < lo; i++) {
        dst[i] = fabs(X(i) - s / w);
        s += X(REFL(i + h + 1)) - X(REFL(i - h));
    }
    if (stride == 8) {
        const double *x = (const double *)base;
        for (Py_ssize_t i = lo; i < hi; i++) {
            dst[i] = fabs((x[i] - y0) - s / w);
            s += x[i + h + 1] - x[i - h];
        }
    } else {
        for (Py_ssize_t i = lo; i < hi; i++) {
            dst[i] = fabs(X(i) - s / w);
            s += X(i + h + 1) - X(i - h);
        }
    }
    for (Py_ssize_t i = hi; i < n; i++) {
        dst[i] = fabs(X(i) - s / w);
        if (i + 1 < n)  /* no window after the last sample (its reflection may not exist) */
            s += X(REFL(i + h + 1)) - X(REFL(i - h));
    }
#undef REFL
#undef X
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&v);
    PyBuffer_Release(&o);
    Py_RETURN_NONE;
}

/* first_order(x, b0, b1, a1, z, out): the first-order IIR filter y_i = z + b0 x_i,
   z <- b1 x_i - a1 y_i (a0 = 1), from the state z; scipy.signal.lfilter's direct form II
   transposed, the same operations in the same order (the thermal lag of avard explain,
   core/explain/thermal_fit.lag_filter; general path: lfilter itself). Returns the last z. */
static PyObject *
kernels_first_order(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    Py_buffer v, o;
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "first_order(x, b0, b1, a1, z, out) takes 6 arguments");
        return NULL;
    }
    const double b0 = PyFloat_AsDouble(args[1]), b1 = PyFloat_AsDouble(args[2]),
                 a1 = PyFloat_AsDouble(args[3]);
    double z = PyFloat_AsDouble(args[4]);
    if (PyErr_Occurred())
        return NULL;
    if (get_in_out(args[0], args[5], &v, &o, 0, "x") < 0)
        return NULL;
    const Py_ssize_t n = v.shape[0];
    if (o.shape[0] != n) {
        PyErr_SetString(PyExc_ValueError, "out must be as long as x");
        return release2(&v, &o);
    }
    const double *x = v.buf;
    double *y = o.buf;
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < n; i++) {
        const double xi = x[i];
        const double yi = z + b0 * xi;
        y[i] = yi;
        z = b1 * xi - a1 * yi;
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&v);
    PyBuffer_Release(&o);
    return PyFloat_FromDouble(z);
}

static PyMethodDef kernels_methods[] = {
    {"sumsq", (PyCFunction)(void (*)(void))kernels_sumsq, METH_FASTCALL,
     "sumsq(x0, x1, x2): sum of ((x2 - x1) - (x1 - x0))**2 over float64 vectors"},
    {"sumsq_ring", (PyCFunction)(void (*)(void))kernels_sumsq_ring, METH_FASTCALL,
     "sumsq_ring(ring, spans, out): sumsq of every channel at many tau of a ring"},
    {"sumsq_mod", (PyCFunction)(void (*)(void))kernels_sumsq_mod, METH_FASTCALL,
     "sumsq_mod(x0, x1, x2, ring, k, last): sumsq and the modified AVAR's running sums"},
    {"running_sum", (PyCFunction)(void (*)(void))kernels_running_sum, METH_FASTCALL,
     "running_sum(y, offset, carry, out): out = carry + cumsum(y - offset); the last value"},
    {"power_sum", (PyCFunction)(void (*)(void))kernels_power_sum, METH_FASTCALL,
     "power_sum(spec, k, out): out += the sum over k blocks of |spec|^2"},
    {"lag_sums", (PyCFunction)(void (*)(void))kernels_lag_sums, METH_FASTCALL,
     "lag_sums(x, m, ref, out, old): the averages' sum and lag products, added to out"},
    {"local_residual", (PyCFunction)(void (*)(void))kernels_local_residual, METH_FASTCALL,
     "local_residual(y, half, out): out = |y - y[0] - its reflected moving mean|"},
    {"first_order", (PyCFunction)(void (*)(void))kernels_first_order, METH_FASTCALL,
     "first_order(x, b0, b1, a1, z, out): lfilter([b0, b1], [1, a1], x, zi=[z]); last z"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef kernels_module = {
    PyModuleDef_HEAD_INIT, "_kernels",
    "Compiled inner loops of avard analyze: the OADEV, its noise identification, the "
    "Welch spectrum and the input screen (optional).", -1,
    kernels_methods, NULL, NULL, NULL, NULL,
};

/* The interface version avard.core.allan.kernels expects (its API): raise both together. */
#define KERNELS_API 5

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
