/* Compiled slip model (measurement.inference.slip_model.slip_displacement): the ball's
 * displacement along the rim for candidate pairs (mu, mu_d), one candidate row at a time.
 *
 * Why compiled: the NumPy reference (_slip_displacement_numpy) makes ~20 passes over (M, N)
 * arrays and one exp per element, stuck columns included, and loops over slip episodes in
 * Python; a 3072-frame analysis spent 0.05-0.10 s of CPU there (benchmarks/bench_slip_model.py,
 * seeds 1-3). Here each row is walked once: a compare
 * per stuck sample, one exp per slipping sample.
 *
 * The same model and discretisation as the reference: stuck until q > mu, a sub-sample onset
 * between the last stuck sample and the first slipping one, then the integrating-factor form
 *     u_k = (u_is + S_k) / E_k,  E_k = exp(clip(C_k) - clip(C_is)),  S_k = sum trapezoids(E g)
 * (C the trapezoid integral of c = mu_d s omega (2 - 0.2 d/l) / 1.4 from the call's first
 * column, clipped at +-50 as the reference does), re-stick at the first sample with u < 0,
 * displacement the trapezoid integral of u, episodes until the record ends or the cap. The
 * reference accumulates E and S from the call's first column and divides; here they are
 * relative to the episode's onset sample (equal in exact arithmetic, fewer rounding errors),
 * so the two agree to rounding (tests/test_slip_kernel.py: <= 1e-9 of max|D|).
 *
 * t is taken as uniform, as in the reference: the step is t[1] - t[0] (refused unless > 0);
 * NaN/inf in any input is refused (ValueError), the caller then runs the reference.
 *
 * A plain CPython extension: arrays arrive through the buffer protocol (C-contiguous float64,
 * checked here), so no NumPy headers are needed to build it.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

/* One C-contiguous float64 buffer of ``count`` doubles, or a ValueError/TypeError. */
static int get_doubles(PyObject *obj, Py_buffer *b, int writable, const char *name)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, b, flags) != 0) {
        if (PyErr_ExceptionMatches(PyExc_BufferError)
            || PyErr_ExceptionMatches(PyExc_ValueError)) {
            PyErr_Clear();
            PyErr_Format(PyExc_ValueError,
                         "_slipc: '%s' must be a C-contiguous%s float64 buffer", name,
                         writable ? ", writable" : "");
        } else if (PyErr_ExceptionMatches(PyExc_TypeError)) {
            PyErr_Clear();
            PyErr_Format(PyExc_TypeError, "_slipc: '%s' must support the buffer protocol "
                         "(got %.80s)", name, Py_TYPE(obj)->tp_name);
        }
        return 0;
    }
    const char *f = b->format ? b->format : "B";
    if (f[0] == '@' || f[0] == '=') f++;
#if PY_LITTLE_ENDIAN
    else if (f[0] == '<') f++;
#else
    else if (f[0] == '>' || f[0] == '!') f++;
#endif
    if (strcmp(f, "d") != 0 || b->itemsize != 8) {
        PyErr_Format(PyExc_TypeError, "_slipc: '%s' must hold float64 (format 'd'), got "
                     "format '%s'", name, b->format ? b->format : "B");
        PyBuffer_Release(b);
        return 0;
    }
    return 1;
}

static int count_is(Py_buffer *b, Py_ssize_t n, const char *name)
{
    if (b->len / 8 != n) {
        PyErr_Format(PyExc_ValueError, "_slipc: '%s' holds %zd values, needs %zd", name,
                     b->len / 8, n);
        return 0;
    }
    return 1;
}

/* Every value finite, or a ValueError naming the first one that is not. */
static int all_finite(const double *v, Py_ssize_t n, const char *name)
{
    for (Py_ssize_t k = 0; k < n; k++)
        if (!isfinite(v[k])) {
            PyErr_Format(PyExc_ValueError, "_slipc: '%s' holds a non-finite value at index %zd",
                         name, k);
            return 0;
        }
    return 1;
}

/* Whether two buffers share a byte (an output written while an input is still read). */
static int overlap(const Py_buffer *a, const Py_buffer *b)
{
    uintptr_t a0 = (uintptr_t)a->buf, b0 = (uintptr_t)b->buf;
    return a->len > 0 && b->len > 0 && a0 < b0 + (uintptr_t)b->len
           && b0 < a0 + (uintptr_t)a->len;
}

static double clip50(double v) { return v < -50.0 ? -50.0 : (v > 50.0 ? 50.0 : v); }

typedef struct {
    const double *t, *q, *w2, *cw;      /* times, q, omega^2, trapezoid integral of omega */
    Py_ssize_t n;
    double h, coef;                     /* step [s]; (2 - 0.2 d/l) s / 1.4 */
    Py_ssize_t cap;                     /* episodes followed (< 0: all) */
} Record;

/* One candidate row: D (n values) and the first onset time. */
static void one_row(const Record *r, double mu, double mud, double *D, double *onset)
{
    const double *t = r->t, *q = r->q, *w2 = r->w2, *cw = r->cw, h = r->h;
    const Py_ssize_t n = r->n;
    const double a = mud * r->coef;      /* C_k = a * cw_k: the integral of c */
    double base = 0.0;                   /* displacement of the episodes before */
    Py_ssize_t filled = 0, start = 0, episodes = 0;
    *onset = INFINITY;
    while (r->cap < 0 || episodes < r->cap) {
        Py_ssize_t is = start;
        while (is < n && !(q[is] > mu)) is++;
        if (is >= n) break;
        episodes++;
        /* sub-sample onset between is - 1 and is (q crosses mu there) */
        Py_ssize_t prev = is > 0 ? is - 1 : 0;
        double q0 = q[prev], q1 = q[is], frac = 1.0;
        if (is > start && q1 > q0) frac = (mu - q0) / (q1 - q0);
        frac = frac < 0.0 ? 0.0 : (frac > 1.0 ? 1.0 : frac);
        double delta = (1.0 - frac) * h;                 /* time from onset to t[is] */
        if (episodes == 1) *onset = t[is] - delta;
        double g_on = w2[prev] * (mu - mud) / 1.4;
        double g_prev = (q1 - mud) * w2[is] / 1.4;
        const double u_is = 0.5 * (g_on + g_prev) * delta; /* slip speed at t[is] */
        double u_prev = u_is, d = 0.5 * u_is * delta;
        for (Py_ssize_t k = filled; k < is; k++) D[k] = base;
        D[is] = base + d;
        if (u_is < 0.0) {          /* mu_d > mu: re-stick at once, slip again from rest */
            base += d;
            filled = is + 1;
            start = is;
            continue;
        }
        /* u_k = (u_is + S_k) / E_k, E and S relative to the onset sample */
        const double c_is = clip50(a * cw[is]);
        double eg_prev = g_prev, s = 0.0;
        Py_ssize_t k = is + 1;
        for (; k < n; k++) {
            double e = exp(clip50(a * cw[k]) - c_is);
            double eg = e * ((q[k] - mud) * w2[k] / 1.4);
            s += (eg + eg_prev) * 0.5 * h;
            double u = (u_is + s) / e;
            if (u < 0.0) break;                          /* re-stick at k */
            d += (u + u_prev) * 0.5 * h;
            D[k] = base + d;
            u_prev = u;
            eg_prev = eg;
        }
        if (k >= n) { filled = n; base += d; break; }    /* slips to the record's end */
        d += u_prev * 0.5 * h;                           /* u reaches 0 at the re-stick */
        base += d;
        D[k] = base;
        filled = k + 1;
        start = k;                                       /* the next onset is searched from k */
    }
    for (Py_ssize_t k = filled; k < n; k++) D[k] = base;
}

static PyObject *slip(PyObject *Py_UNUSED(self), PyObject *args)
{
    PyObject *ot, *oq, *ow, *omu, *omud, *oD, *oon;
    double direction, d_over_l;
    Py_ssize_t cap;
    if (!PyArg_ParseTuple(args, "OOOOOddnOO", &ot, &oq, &ow, &omu, &omud, &direction,
                          &d_over_l, &cap, &oD, &oon))
        return NULL;
    Py_buffer b[7];
    PyObject *objs[7] = {ot, oq, ow, omu, omud, oD, oon};
    const char *names[7] = {"t", "q", "omega", "mu", "mu_d", "D", "onset"};
    int got = 0;
    PyObject *ret = NULL;
    double *work = NULL;
    for (; got < 7; got++)
        if (!get_doubles(objs[got], &b[got], got >= 5, names[got])) goto done;
    const Py_ssize_t n = b[0].len / 8, m = b[3].len / 8;
    if (n < 2) {
        PyErr_SetString(PyExc_ValueError, "_slipc: 't' needs at least 2 samples");
        goto done;
    }
    if (!count_is(&b[1], n, "q") || !count_is(&b[2], n, "omega")
        || !count_is(&b[4], m, "mu_d") || !count_is(&b[6], m, "onset"))
        goto done;
    /* sizes first: they are checked without reading the values */
    if (m > 0 && n > PY_SSIZE_T_MAX / 8 / m) {
        PyErr_SetString(PyExc_ValueError, "_slipc: 'D' too large");
        goto done;
    }
    if (!count_is(&b[5], m * n, "D")) goto done;
    for (int o = 5; o < 7; o++)
        for (int i = 0; i < o; i++)
            if (overlap(&b[o], &b[i])) {
                PyErr_Format(PyExc_ValueError, "_slipc: '%s' overlaps '%s'", names[o],
                             names[i]);
                goto done;
            }
    /* NaN/inf would not fail here but give rows that differ from the reference's (its
     * cumulative sums carry a NaN into every later episode, this kernel restarts them) */
    for (int i = 0; i < 5; i++)
        if (!all_finite(b[i].buf, b[i].len / 8, names[i])) goto done;
    if (!isfinite(direction) || !isfinite(d_over_l)) {
        PyErr_SetString(PyExc_ValueError, "_slipc: 'direction' and 'd_over_l' must be finite");
        goto done;
    }
    {
        const double *t = b[0].buf;
        if (!(t[1] - t[0] > 0.0 && isfinite(t[1] - t[0]))) {
            PyErr_SetString(PyExc_ValueError, "_slipc: 't' must increase (t[1] > t[0])");
            goto done;
        }
    }
    work = malloc(sizeof(double) * 2 * (size_t)n);
    if (!work) { PyErr_NoMemory(); goto done; }
    {
        const double *t = b[0].buf, *w = b[2].buf, *mu = b[3].buf, *mud = b[4].buf;
        double *D = b[5].buf, *onset = b[6].buf;
        Record r = {t, b[1].buf, work, work + n, n, t[1] - t[0],
                    (2.0 - 0.2 * d_over_l) * direction / 1.4, cap};
        Py_BEGIN_ALLOW_THREADS
        double *w2 = work, *cw = work + n;
        cw[0] = 0.0;
        for (Py_ssize_t k = 0; k < n; k++) {
            w2[k] = w[k] * w[k];
            if (k > 0) cw[k] = cw[k - 1] + (w[k] + w[k - 1]) * 0.5 * r.h;
        }
        for (Py_ssize_t i = 0; i < m; i++) one_row(&r, mu[i], mud[i], D + i * n, onset + i);
        Py_END_ALLOW_THREADS
    }
    ret = Py_NewRef(Py_None);
done:
    free(work);
    for (int i = 0; i < got; i++) PyBuffer_Release(&b[i]);
    return ret;
}

static PyMethodDef methods[] = {
    {"slip", slip, METH_VARARGS,
     "slip(t, q, omega, mu, mu_d, direction, d_over_l, max_episodes, D, onset): the slip "
     "displacement D (M*N float64, written) and first onset times (M float64, written) of M "
     "candidates (mu, mu_d) over N uniform samples; max_episodes < 0: every episode."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_slipc",
                                    "Compiled slip model of measurement.inference.slip_model.",
                                    -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__slipc(void) { return PyModule_Create(&module); }
