/* The recording scan's frame loop in C: avard.core.io._framescan.
 *
 * Opening a recording checks every frame (u32 length | u32 crc32 | msgpack payload, see
 * core/io/recording.py) and reads the sample index of every raw block. Done a frame at a time
 * in Python that was most of `avard analyze`'s time on a long recording (a 60 h recording at
 * 125 Hz holds over a million frames). This is the same loop in C, and nothing more: it stops
 * at the first frame that does not check (the Python reader then reports and resynchronises
 * exactly as for any reader), and it reads only raw records laid out exactly as
 * frames.raw_record encodes them; every other record it hands back to the general decoder.
 * So what it accepts is a strict subset of what frames.decode accepts, with the same values
 * (tests/core/test_recording_fastscan.py holds the two paths equal, on damaged segments too).
 * The build is optional (setup.py): without it the scan takes the general path.
 *
 *   scan(buf, base, max_bytes) -> (consumed, status, entries)
 *       Walks the frames of buf from its start. status 0: stopped at the end of buf or at a
 *       frame that runs past it (more data may complete it); status 1: stopped at a frame
 *       whose length is 0 or above max_bytes or whose CRC does not match. consumed: bytes of
 *       buf in the frames walked. entries: bytes holding ENTRY_FIELDS int64 per frame that
 *       is not a temp/avar/checkpoint/status record (those are checked, then skipped as the
 *       Python scan skips them by their kind): offset (base + position in buf), payload
 *       length, code (1: a raw record read here; 2: decode it in Python; 3: the same, its
 *       kind "header"), i0, n, offset of the counts (base + position), offset of the run id
 *       (base + position), its length, and 1 when the entry before it in this call, past any
 *       header entries, is a raw record read here of the same run (else 0).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <string.h>
#include <stdint.h>
#include <zlib.h>

#define ENTRY_FIELDS 9
#define API 3

/* CRC-32 (zlib's) by carry-less multiplication where the CPU has it (x86-64 PCLMULQDQ and
 * SSE4.1, checked at run time): zlib's table loop was about half the C loop's time on a long
 * recording. Folding four 128-bit lanes, then Barrett reduction, after Intel's "Fast CRC
 * Computation for Generic Polynomials Using PCLMULQDQ" (the reflected constants of zlib's
 * polynomial, as Chromium's zlib and Linux's crc32-pclmul use them). zlib does the tail
 * under 16 bytes, lengths under 64 and every other CPU; tests/core/test_recording_fastscan.py
 * holds crc32() equal to zlib.crc32 on every length and alignment around the boundaries. */
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define HAVE_CLMUL 1

__attribute__((target("pclmul,sse4.1"))) static uint32_t
crc_fold(const unsigned char *buf, size_t len, uint32_t crc)   /* len >= 64, len % 16 == 0 */
{
    static const uint64_t __attribute__((aligned(16))) k1k2[] = {0x0154442bd4, 0x01c6e41596};
    static const uint64_t __attribute__((aligned(16))) k3k4[] = {0x01751997d0, 0x00ccaa009e};
    static const uint64_t __attribute__((aligned(16))) k5k0[] = {0x0163cd6124, 0x0000000000};
    static const uint64_t __attribute__((aligned(16))) poly[] = {0x01db710641, 0x01f7011641};
    __m128i x0, x1, x2, x3, x4, x5, x6, x7, x8, y5, y6, y7, y8;

    x1 = _mm_loadu_si128((const __m128i *)(buf + 0x00));
    x2 = _mm_loadu_si128((const __m128i *)(buf + 0x10));
    x3 = _mm_loadu_si128((const __m128i *)(buf + 0x20));
    x4 = _mm_loadu_si128((const __m128i *)(buf + 0x30));
    x1 = _mm_xor_si128(x1, _mm_cvtsi32_si128((int)crc));
    x0 = _mm_load_si128((const __m128i *)k1k2);
    buf += 64;
    len -= 64;
    while (len >= 64) {
        x5 = _mm_clmulepi64_si128(x1, x0, 0x00);
        x6 = _mm_clmulepi64_si128(x2, x0, 0x00);
        x7 = _mm_clmulepi64_si128(x3, x0, 0x00);
        x8 = _mm_clmulepi64_si128(x4, x0, 0x00);
        x1 = _mm_clmulepi64_si128(x1, x0, 0x11);
        x2 = _mm_clmulepi64_si128(x2, x0, 0x11);
        x3 = _mm_clmulepi64_si128(x3, x0, 0x11);
        x4 = _mm_clmulepi64_si128(x4, x0, 0x11);
        y5 = _mm_loadu_si128((const __m128i *)(buf + 0x00));
        y6 = _mm_loadu_si128((const __m128i *)(buf + 0x10));
        y7 = _mm_loadu_si128((const __m128i *)(buf + 0x20));
        y8 = _mm_loadu_si128((const __m128i *)(buf + 0x30));
        x1 = _mm_xor_si128(_mm_xor_si128(x1, x5), y5);
        x2 = _mm_xor_si128(_mm_xor_si128(x2, x6), y6);
        x3 = _mm_xor_si128(_mm_xor_si128(x3, x7), y7);
        x4 = _mm_xor_si128(_mm_xor_si128(x4, x8), y8);
        buf += 64;
        len -= 64;
    }
    /* the four lanes into one */
    x0 = _mm_load_si128((const __m128i *)k3k4);
    x5 = _mm_clmulepi64_si128(x1, x0, 0x00);
    x1 = _mm_clmulepi64_si128(x1, x0, 0x11);
    x1 = _mm_xor_si128(_mm_xor_si128(x1, x2), x5);
    x5 = _mm_clmulepi64_si128(x1, x0, 0x00);
    x1 = _mm_clmulepi64_si128(x1, x0, 0x11);
    x1 = _mm_xor_si128(_mm_xor_si128(x1, x3), x5);
    x5 = _mm_clmulepi64_si128(x1, x0, 0x00);
    x1 = _mm_clmulepi64_si128(x1, x0, 0x11);
    x1 = _mm_xor_si128(_mm_xor_si128(x1, x4), x5);
    while (len >= 16) {
        x2 = _mm_loadu_si128((const __m128i *)buf);
        x5 = _mm_clmulepi64_si128(x1, x0, 0x00);
        x1 = _mm_clmulepi64_si128(x1, x0, 0x11);
        x1 = _mm_xor_si128(_mm_xor_si128(x1, x2), x5);
        buf += 16;
        len -= 16;
    }
    /* 128 bits to 64, then Barrett reduction to 32 */
    x2 = _mm_clmulepi64_si128(x1, x0, 0x10);
    x3 = _mm_setr_epi32(~0, 0, ~0, 0);
    x1 = _mm_srli_si128(x1, 8);
    x1 = _mm_xor_si128(x1, x2);
    x0 = _mm_loadl_epi64((const __m128i *)k5k0);
    x2 = _mm_srli_si128(x1, 4);
    x1 = _mm_and_si128(x1, x3);
    x1 = _mm_clmulepi64_si128(x1, x0, 0x00);
    x1 = _mm_xor_si128(x1, x2);
    x0 = _mm_load_si128((const __m128i *)poly);
    x2 = _mm_and_si128(x1, x3);
    x2 = _mm_clmulepi64_si128(x2, x0, 0x10);
    x2 = _mm_and_si128(x2, x3);
    x2 = _mm_clmulepi64_si128(x2, x0, 0x00);
    x1 = _mm_xor_si128(x1, x2);
    return (uint32_t)_mm_extract_epi32(x1, 1);
}
#endif

static int have_clmul = 0;      /* set at import */

/* zlib's crc32 of n bytes (any n), starting from zlib's crc32 value ``crc``. */
static uint32_t
crc_bytes(uint32_t crc, const unsigned char *p, size_t n)
{
#ifdef HAVE_CLMUL
    if (have_clmul && n >= 64) {
        size_t m = n & ~(size_t)15;
        crc = ~crc_fold(p, m, ~crc);
        p += m;
        n -= m;
    }
#endif
    uLong got = crc;
    size_t done = 0;
    while (done < n) {          /* zlib's crc32 takes a uInt length */
        uInt part = (uInt)((n - done) > 0x40000000u ? 0x40000000u : (n - done));
        got = crc32(got, p + done, part);
        done += part;
    }
    return (uint32_t)got;
}

typedef struct {
    const unsigned char *p;
    const unsigned char *end;
} cursor;

static uint32_t
le32(const unsigned char *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16)
           | ((uint32_t)p[3] << 24);
}

static uint64_t
be(const unsigned char *p, int n)
{
    uint64_t v = 0;
    for (int i = 0; i < n; i++)
        v = (v << 8) | p[i];
    return v;
}

/* A msgpack string (fixstr, str8, str16, str32): its bytes. */
static int
rd_str(cursor *c, const unsigned char **s, size_t *len)
{
    if (c->p >= c->end)
        return 0;
    unsigned char t = *c->p++;
    size_t n, w = 0;
    if (t >= 0xa0 && t <= 0xbf)
        n = t - 0xa0;
    else if (t == 0xd9) w = 1;
    else if (t == 0xda) w = 2;
    else if (t == 0xdb) w = 4;
    else
        return 0;
    if (w) {
        if ((size_t)(c->end - c->p) < w)
            return 0;
        n = (size_t)be(c->p, (int)w);
        c->p += w;
    }
    if ((size_t)(c->end - c->p) < n)
        return 0;
    *s = c->p;
    *len = n;
    c->p += n;
    return 1;
}

static int
key_is(cursor *c, const char *want)
{
    const unsigned char *s;
    size_t n;
    if (!rd_str(c, &s, &n))
        return 0;
    return n == strlen(want) && memcmp(s, want, n) == 0;
}

/* A non-negative integer in an unsigned msgpack format, at most 2^62 (what frames.decode
 * gives as a Python int >= 0; the signed formats are left to it). */
static int
rd_uint(cursor *c, int64_t *v)
{
    if (c->p >= c->end)
        return 0;
    unsigned char t = *c->p++;
    int w;
    if (t <= 0x7f) {
        *v = t;
        return 1;
    }
    if (t == 0xcc) w = 1;
    else if (t == 0xcd) w = 2;
    else if (t == 0xce) w = 4;
    else if (t == 0xcf) w = 8;
    else
        return 0;
    if (c->end - c->p < w)
        return 0;
    uint64_t u = be(c->p, w);
    c->p += w;
    if (u > ((uint64_t)1 << 62))
        return 0;
    *v = (int64_t)u;
    return 1;
}

/* A number (int or float, as the schema's "num"); with nil_ok also nil ("num|none"). */
static int
skip_num(cursor *c, int nil_ok)
{
    if (c->p >= c->end)
        return 0;
    unsigned char t = *c->p++;
    int w;
    if (t <= 0x7f || t >= 0xe0)
        return 1;
    if (t == 0xc0)
        return nil_ok;
    if (t == 0xca) w = 4;
    else if (t == 0xcb) w = 8;
    else if (t == 0xcc || t == 0xd0) w = 1;
    else if (t == 0xcd || t == 0xd1) w = 2;
    else if (t == 0xce || t == 0xd2) w = 4;
    else if (t == 0xcf || t == 0xd3) w = 8;
    else
        return 0;
    if (c->end - c->p < w)
        return 0;
    c->p += w;
    return 1;
}

/* A raw record exactly as frames.raw_record encodes it: a map of kind "raw", v 1, run (an
 * ASCII string), seq, i0, n, t_mono, t_real, counts {dtype "<i4", shape [n, 3], data of
 * 12 n bytes, n >= 1}, then rate_hz and chip_temp_c if present, in that order, and nothing
 * after. Anything else returns 0: the general decoder reads it. */
static int
parse_raw(const unsigned char *pay, size_t len, int64_t *i0, int64_t *n,
          const unsigned char **counts, const unsigned char **run, size_t *run_len)
{
    cursor c = {pay, pay + len};
    if (len < 1 || pay[0] < 0x89 || pay[0] > 0x8b)
        return 0;
    int entries = pay[0] - 0x80;
    c.p++;
    const unsigned char *s;
    size_t sn;
    int64_t v, seq, dim;
    if (!key_is(&c, "kind") || !rd_str(&c, &s, &sn) || sn != 3 || memcmp(s, "raw", 3) != 0)
        return 0;
    if (!key_is(&c, "v") || !rd_uint(&c, &v) || v != 1)
        return 0;
    if (!key_is(&c, "run") || !rd_str(&c, run, run_len))
        return 0;
    for (size_t k = 0; k < *run_len; k++)
        if ((*run)[k] >= 0x80)
            return 0;
    if (!key_is(&c, "seq") || !rd_uint(&c, &seq))
        return 0;
    if (!key_is(&c, "i0") || !rd_uint(&c, i0))
        return 0;
    if (!key_is(&c, "n") || !rd_uint(&c, n) || *n < 1 || *n > ((int64_t)1 << 40))
        return 0;
    if (!key_is(&c, "t_mono") || !skip_num(&c, 0))
        return 0;
    if (!key_is(&c, "t_real") || !skip_num(&c, 0))
        return 0;
    if (!key_is(&c, "counts") || c.p >= c.end || *c.p++ != 0x83)
        return 0;
    if (!key_is(&c, "dtype") || !rd_str(&c, &s, &sn) || sn != 3 || memcmp(s, "<i4", 3) != 0)
        return 0;
    if (!key_is(&c, "shape") || c.p >= c.end || *c.p++ != 0x92)
        return 0;
    if (!rd_uint(&c, &dim) || dim != *n || !rd_uint(&c, &dim) || dim != 3)
        return 0;
    if (!key_is(&c, "data") || c.p >= c.end)
        return 0;
    unsigned char t = *c.p++;
    int w = t == 0xc4 ? 1 : t == 0xc5 ? 2 : t == 0xc6 ? 4 : 0;
    if (!w || c.end - c.p < w)
        return 0;
    uint64_t bytes = be(c.p, w);
    c.p += w;
    if (bytes != (uint64_t)*n * 12 || (uint64_t)(c.end - c.p) < bytes)
        return 0;
    *counts = c.p;
    c.p += bytes;
    int more = entries - 9;
    if (more >= 1) {
        const unsigned char *keep = c.p;
        if (key_is(&c, "rate_hz")) {
            if (!skip_num(&c, 0))
                return 0;
            more--;
        }
        else
            c.p = keep;
    }
    if (more >= 1) {
        if (!key_is(&c, "chip_temp_c") || !skip_num(&c, 1))
            return 0;
        more--;
    }
    return more == 0 && c.p == c.end;
}

/* The record's kind from its first bytes (frames.encode writes "kind" first), compared with
 * ``name`` as source.py's _peek_kind compares it (a string cut short by the payload's end is
 * what is left of it, as Python's slice). */
static int
kind_is(const unsigned char *pay, size_t len, const char *name)
{
    if (len < 1)
        return 0;
    unsigned char b0 = pay[0];
    size_t i = (b0 >= 0x80 && b0 <= 0x8f) ? 1 : b0 == 0xde ? 3 : b0 == 0xdf ? 5 : 0;
    if (!i || len <= i + 5 || memcmp(pay + i, "\xa4kind", 5) != 0)
        return 0;
    int size = (int)pay[i + 5] - 0xa0;
    if (size < 0 || size >= 32)
        return 0;
    size_t have = len - i - 6 < (size_t)size ? len - i - 6 : (size_t)size;
    return have == strlen(name) && memcmp(pay + i + 6, name, have) == 0;
}

/* Whether the record is of a kind the scan skips. */
static int
skipped_kind(const unsigned char *pay, size_t len)
{
    static const char *names[] = {"temp", "avar", "checkpoint", "status"};
    for (int j = 0; j < 4; j++)
        if (kind_is(pay, len, names[j]))
            return 1;
    return 0;
}

static PyObject *
scan(PyObject *self, PyObject *args)
{
    Py_buffer view;
    long long base, max_bytes;
    if (!PyArg_ParseTuple(args, "y*LL", &view, &base, &max_bytes))
        return NULL;
    const unsigned char *buf = (const unsigned char *)view.buf;
    size_t size = (size_t)view.len, pos = 0, count = 0, cap = 1024;
    int status = 0;
    const unsigned char *prev_run = NULL;      /* the run of the entry before, if raw */
    size_t prev_len = 0;
    int64_t *out = (int64_t *)PyMem_Malloc(cap * ENTRY_FIELDS * sizeof(int64_t));
    if (out == NULL) {
        PyBuffer_Release(&view);
        return PyErr_NoMemory();
    }
    Py_BEGIN_ALLOW_THREADS
    while (pos + 8 <= size) {
        uint32_t n = le32(buf + pos), crc = le32(buf + pos + 4);
        if (n == 0 || (long long)n > max_bytes) {
            status = 1;
            break;
        }
        if ((size_t)n > size - pos - 8)
            break;
        const unsigned char *pay = buf + pos + 8;
        if (crc_bytes(0, pay, n) != crc) {
            status = 1;
            break;
        }
        if (!skipped_kind(pay, n)) {
            if (count == cap) {
                int64_t *more = (int64_t *)PyMem_Realloc(
                    out, 2 * cap * ENTRY_FIELDS * sizeof(int64_t));
                if (more == NULL) {
                    status = -1;
                    break;
                }
                out = more;
                cap *= 2;
            }
            int64_t *e = out + count * ENTRY_FIELDS;
            int64_t i0 = 0, k = 0;
            const unsigned char *counts = NULL, *run = NULL;
            size_t run_len = 0;
            int raw = parse_raw(pay, n, &i0, &k, &counts, &run, &run_len);
            e[0] = base + (int64_t)pos;
            e[1] = n;
            int head = !raw && kind_is(pay, n, "header");
            e[2] = raw ? 1 : head ? 3 : 2;
            e[3] = raw ? i0 : 0;
            e[4] = raw ? k : 0;
            e[5] = raw ? base + (int64_t)(counts - buf) : -1;
            e[6] = raw ? base + (int64_t)(run - buf) : -1;
            e[7] = raw ? (int64_t)run_len : 0;
            e[8] = raw && prev_run != NULL && prev_len == run_len
                   && memcmp(prev_run, run, run_len) == 0;
            if (raw) {
                prev_run = run;
                prev_len = run_len;
            }
            else if (!head)             /* header records do not part a raw one from the last */
                prev_run = NULL;
            count++;
        }
        pos += 8 + (size_t)n;
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&view);
    if (status < 0) {
        PyMem_Free(out);
        return PyErr_NoMemory();
    }
    PyObject *entries = PyBytes_FromStringAndSize(
        (const char *)out, (Py_ssize_t)(count * ENTRY_FIELDS * sizeof(int64_t)));
    PyMem_Free(out);
    if (entries == NULL)
        return NULL;
    return Py_BuildValue("(niN)", (Py_ssize_t)pos, status, entries);
}

static PyObject *
crc(PyObject *self, PyObject *args)
{
    Py_buffer view;
    unsigned int start = 0;
    if (!PyArg_ParseTuple(args, "y*|I", &view, &start))
        return NULL;
    uint32_t got;
    Py_BEGIN_ALLOW_THREADS
    got = crc_bytes(start, (const unsigned char *)view.buf, (size_t)view.len);
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&view);
    return PyLong_FromUnsignedLong(got);
}

static PyMethodDef framescan_methods[] = {
    {"crc32", crc, METH_VARARGS,
     "crc32(buf[, start]) -> zlib.crc32(buf, start), by the scan's own CRC"},
    {"scan", scan, METH_VARARGS,
     "scan(buf, base, max_bytes) -> (consumed, status, entries): see _framescan.c"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef framescan_module = {
    PyModuleDef_HEAD_INIT, "_framescan",
    "The recording scan's frame loop (core/io/_framescan.c).", -1, framescan_methods,
};

PyMODINIT_FUNC
PyInit__framescan(void)
{
#ifdef HAVE_CLMUL
    __builtin_cpu_init();
    have_clmul = __builtin_cpu_supports("pclmul") && __builtin_cpu_supports("sse4.1");
#endif
    PyObject *m = PyModule_Create(&framescan_module);
    if (m != NULL && (PyModule_AddIntConstant(m, "API", API) < 0
                      || PyModule_AddIntConstant(m, "ENTRY_FIELDS", ENTRY_FIELDS) < 0
                      || PyModule_AddIntConstant(m, "CLMUL", have_clmul) < 0)) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
