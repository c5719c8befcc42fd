/* Compiled kernels of the tracker (measurement.imaging.tracking): the seeded pass and the
 * isocontour refinement, one window at a time.
 *
 * Why compiled: the seeded pass is sequential (each window sits where the previous frame put
 * the marker), so in Python it costs three OpenCV calls and the interpreter per window (~75 ms
 * for 3072 frames x 3 markers); the NumPy refinement spends most of its time allocating and
 * re-reading (K, 30, 30) temporaries (~110 ms). Here each window stays in L1 cache.
 *
 * Both kernels do the same arithmetic, in the same order, as the NumPy code they replace
 * (track_passes._seeded_chunk_py, window_fits.refine_isocontour and edge_step.edge_step): the
 * seeded pass is exact (integer moments), the refinement agrees to ~1e-13 px (some sums in
 * another order; tests/test_tracking_kernels.py).
 *
 * A plain CPython extension: arrays arrive through the buffer protocol (C-contiguous, checked
 * by the Python wrapper), so no NumPy headers are needed to build it.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* reason codes, as window_fits.OK ... JUMP */
enum { OK = 0, OUTSIDE = 1, LOW_CONTRAST = 2, TOUCHES_EDGE = 3, FIT_FAILED = 4, BAD_RADIUS = 5,
       JUMP = 6 };

static int need(Py_buffer *b, Py_ssize_t bytes, const char *name)
{
    if (b->len < bytes) {
        PyErr_Format(PyExc_ValueError, "_trackc: buffer '%s' holds %zd bytes, needs %zd",
                     name, b->len, bytes);
        return 0;
    }
    return 1;
}

/* round half to even, as Python's round() and np.rint (default rounding mode) */
static double rne(double v) { return nearbyint(v); }

/* ---------------------------------------------------------------------------------------- */
/* seeded pass */

static PyObject *seeded(PyObject *Py_UNUSED(self), PyObject *args)
{
    Py_buffer fb, st, bx, by, br;
    Py_ssize_t nf, h, w, mc, win;
    int dark;
    double min_contrast, max_jump;
    if (!PyArg_ParseTuple(args, "y*nnnnnpddw*w*w*w*", &fb, &nf, &h, &w, &mc, &win, &dark,
                          &min_contrast, &max_jump, &st, &bx, &by, &br))
        return NULL;
    PyObject *ret = NULL;
    if (!need(&fb, nf * h * w, "frames") || !need(&st, 4 * mc * 8, "state")
        || !need(&bx, nf * mc * 8, "x") || !need(&by, nf * mc * 8, "y")
        || !need(&br, nf * mc, "reason"))
        goto done;
    {
        const uint8_t *frames = fb.buf;
        double *px = st.buf, *py = px + mc, *vx = py + mc, *vy = vx + mc;
        double *xs = bx.buf, *ys = by.buf;
        uint8_t *reason = br.buf;
        const Py_ssize_t half = win / 2;
        const int inv = dark ? 255 : 0;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t k = 0; k < nf; k++) {
            const uint8_t *frame = frames + k * h * w;
#if defined(__GNUC__)
            /* ask for the next frame's windows now: the rows come from memory, not cache */
            if (k + 1 < nf)
                for (Py_ssize_t m = 0; m < mc; m++) {
                    Py_ssize_t x0 = (Py_ssize_t)(px[m] + 2.0 * vx[m]) - half;
                    Py_ssize_t y0 = (Py_ssize_t)(py[m] + 2.0 * vy[m]) - half;
                    if (x0 < 0 || y0 < 0 || x0 + win > w || y0 + win > h) continue;
                    const uint8_t *nxt = frame + h * w + y0 * w + x0;
                    for (Py_ssize_t i = 0; i < win; i++) {
                        __builtin_prefetch(nxt + i * w);
                        __builtin_prefetch(nxt + i * w + win - 1);
                    }
                }
#endif
            for (Py_ssize_t m = 0; m < mc; m++) {
                double qx = px[m] + vx[m], qy = py[m] + vy[m];
                Py_ssize_t x0 = (Py_ssize_t)rne(qx) - half, y0 = (Py_ssize_t)rne(qy) - half;
                int code = OK;
                double cx = 0.0, cy = 0.0;
                if (x0 < 0 || y0 < 0 || x0 + win > w || y0 + win > h) {
                    code = OUTSIDE;
                } else {
                    int lo = 255, hi = 0;
                    for (Py_ssize_t i = 0; i < win; i++) {
                        const uint8_t *row = frame + (y0 + i) * w + x0;
                        for (Py_ssize_t j = 0; j < win; j++) {
                            int v = row[j] ^ inv; /* 255 - v for dark markers */
                            if (v < lo) lo = v;
                            if (v > hi) hi = v;
                        }
                    }
                    if (hi - lo < min_contrast) {
                        code = LOW_CONTRAST;
                    } else {
                        /* cv2.subtract(win, (lo + hi) / 2): the scalar rounded half to even,
                         * the difference saturated at 0; then cv2.moments (exact integers) */
                        int sum = lo + hi, sub = sum / 2;
                        if ((sum & 1) && (sub & 1)) sub += 1;
                        int64_t m00 = 0, m10 = 0, m01 = 0;
                        for (Py_ssize_t i = 0; i < win; i++) {
                            const uint8_t *row = frame + (y0 + i) * w + x0;
                            int64_t rs = 0, rx = 0;
                            for (Py_ssize_t j = 0; j < win; j++) {
                                int v = (row[j] ^ inv) - sub;
                                if (v > 0) { rs += v; rx += v * j; }
                            }
                            m00 += rs; m10 += rx; m01 += rs * i;
                        }
                        if (m00 <= 0) {
                            code = LOW_CONTRAST;
                        } else {
                            cx = (double)x0 + (double)m10 / (double)m00;
                            cy = (double)y0 + (double)m01 / (double)m00;
                            /* a jump: far from both the last good position and the
                             * prediction (a fast marker moves more than max_jump a frame) */
                            double dx = cx - px[m], dy = cy - py[m];
                            double ex = cx - qx, ey = cy - qy;
                            double j2 = max_jump * max_jump;
                            if (dx * dx + dy * dy > j2 && ex * ex + ey * ey > j2) code = JUMP;
                        }
                    }
                }
                Py_ssize_t o = k * mc + m;
                if (code == OK) {
                    xs[o] = cx; ys[o] = cy;
                    vx[m] = cx - px[m]; vy[m] = cy - py[m];
                    px[m] = cx; py[m] = cy;
                    reason[o] = OK;
                } else {
                    xs[o] = px[m]; ys[o] = py[m];
                    vx[m] = 0.0; vy[m] = 0.0;
                    reason[o] = (uint8_t)code;
                }
            }
        }
        Py_END_ALLOW_THREADS
    }
    ret = Py_NewRef(Py_None);
done:
    PyBuffer_Release(&fb); PyBuffer_Release(&st); PyBuffer_Release(&bx);
    PyBuffer_Release(&by); PyBuffer_Release(&br);
    return ret;
}

/* ---------------------------------------------------------------------------------------- */
/* isocontour refinement */

typedef struct {
    double S, Sx, Sy, Sxx, Syy, Sxy, Sxz, Syz, Sz;
} Sums;

/* Kasa fit from the sums, as window_fits.kasa: returns a, b, r (NaN where it fails). */
static void kasa_solve(const Sums *s, double *a, double *b, double *r)
{
    double A[3][3] = {{s->Sxx, s->Sxy, s->Sx}, {s->Sxy, s->Syy, s->Sy}, {s->Sx, s->Sy, s->S}};
    double rhs[3] = {-s->Sxz, -s->Syz, -s->Sz};
    int ok = s->S >= 3.0;
    /* LU with partial pivoting (as LAPACK's getrf): determinant and solution */
    int perm_sign = 1;
    for (int c = 0; c < 3; c++) {
        int p = c;
        for (int i = c + 1; i < 3; i++)
            if (fabs(A[i][c]) > fabs(A[p][c])) p = i;
        if (p != c) {
            for (int j = 0; j < 3; j++) { double t = A[c][j]; A[c][j] = A[p][j]; A[p][j] = t; }
            double t = rhs[c]; rhs[c] = rhs[p]; rhs[p] = t;
            perm_sign = -perm_sign;
        }
        if (A[c][c] == 0.0) { ok = 0; break; }
        for (int i = c + 1; i < 3; i++) {
            double l = A[i][c] / A[c][c];
            for (int j = c; j < 3; j++) A[i][j] -= l * A[c][j];
            rhs[i] -= l * rhs[c];
        }
    }
    if (ok) {
        double det = perm_sign * A[0][0] * A[1][1] * A[2][2];
        double sm = s->S > 1.0 ? s->S : 1.0;
        ok = fabs(det) > 1e-9 * sm * sm * sm;
    }
    if (!ok) { *a = *b = *r = NAN; return; }
    double sol[3];
    for (int i = 2; i >= 0; i--) {
        double v = rhs[i];
        for (int j = i + 1; j < 3; j++) v -= A[i][j] * sol[j];
        sol[i] = v / A[i][i];
    }
    double aa = -sol[0] / 2.0, bb = -sol[1] / 2.0;
    double r2 = aa * aa + bb * bb - sol[2];
    if (!(r2 > 0.0)) { *a = *b = *r = NAN; return; }
    *a = aa; *b = bb; *r = sqrt(r2);
}

static void add_point(Sums *s, double x, double y)
{
    double z = x * x + y * y;
    s->S += 1.0; s->Sx += x; s->Sy += y;
    s->Sxx += x * x; s->Syy += y * y; s->Sxy += x * y;
    s->Sxz += x * z; s->Syz += y * z; s->Sz += z;
}

/* squared distance of a point from the circle (1e6 where the fit failed). sqrt, not hypot
 * (NumPy's choice): 10x faster, and the same to an ulp at these magnitudes. */
static double dist2(double x, double y, double a, double b, double r)
{
    double dx = x - a, dy = y - b;
    double d = sqrt(dx * dx + dy * dy) - r;
    double dd = d * d;
    return isnan(dd) ? 1e6 : dd;
}

typedef struct {
    Py_ssize_t win, nring;
    const int64_t *ring;
    const double *ring_x, *ring_y;  /* the ring pixels' x - cc, y - cc [px] */
    const double *pinv;   /* (3, nring) */
    int smooth;
    double min_contrast, min_snr, r_min, r_max, max_residual, min_points;
    /* the edge step (edge_step.py): on/off, blur s, band, longest step, Phi and phi tables */
    int edge;
    double edge_width, edge_band, edge_max_step, tab_half, tab_per_unit;
    const double *phi, *dphi;
    Py_ssize_t ntab;
} RefineOpts;

/* linear interpolation in the tables of Phi and phi at u, as edge_step._lookup */
static void lookup2(const RefineOpts *o, double u, double *f, double *fp)
{
    if (u < -o->tab_half) u = -o->tab_half;
    if (u > o->tab_half) u = o->tab_half;
    double q = (u + o->tab_half) * o->tab_per_unit;
    Py_ssize_t i = (Py_ssize_t)q;  /* q >= 0: truncation is floor */
    if (i > o->ntab - 2) i = o->ntab - 2;
    double t = q - (double)i;
    *f = o->phi[i] + t * (o->phi[i + 1] - o->phi[i]);
    *fp = o->dphi[i] + t * (o->dphi[i + 1] - o->dphi[i]);
}

/* Solve the n x n system A x = g (row-major, overwritten) by elimination with partial
 * pivoting; 0 if singular or not finite. */
static int solve_n(double *A, double *g, int n, double *x)
{
    for (int c = 0; c < n; c++) {
        int p = c;
        for (int i = c + 1; i < n; i++)
            if (fabs(A[i * n + c]) > fabs(A[p * n + c])) p = i;
        if (p != c) {
            for (int j = 0; j < n; j++) {
                double t = A[c * n + j]; A[c * n + j] = A[p * n + j]; A[p * n + j] = t;
            }
            double t = g[c]; g[c] = g[p]; g[p] = t;
        }
        if (!(A[c * n + c] != 0.0) || !isfinite(A[c * n + c])) return 0;
        for (int i = c + 1; i < n; i++) {
            double l = A[i * n + c] / A[c * n + c];
            for (int j = c; j < n; j++) A[i * n + j] -= l * A[c * n + j];
            g[i] -= l * g[c];
        }
    }
    for (int i = n - 1; i >= 0; i--) {
        double v = g[i];
        for (int j = i + 1; j < n; j++) v -= A[i * n + j] * x[j];
        x[i] = v / A[i * n + i];
    }
    return 1;
}

/* One Gauss-Newton step of I = o + C Phi((r - |p - (a, b)|) / s) on the pixels within the
 * band of the circle (edge_step.edge_step); moves *a, *b unless it fails or is too long. */
static void edge_step(const double *H, Py_ssize_t w, double *a, double *b, double r, double C,
                      const RefineOpts *o)
{
    if (!isfinite(*a) || !isfinite(*b) || !isfinite(r)) return;
    double A[25] = {0.0}, g[5] = {0.0}, J[5], st[5];
    const double s = o->edge_width;
    /* only the box around the band can hold band pixels */
    double reach = r + o->edge_band;
    Py_ssize_t i0 = (Py_ssize_t)floor(*b - reach), i1 = (Py_ssize_t)ceil(*b + reach);
    Py_ssize_t j0 = (Py_ssize_t)floor(*a - reach), j1 = (Py_ssize_t)ceil(*a + reach);
    if (i0 < 0) i0 = 0;
    if (j0 < 0) j0 = 0;
    if (i1 > w - 1) i1 = w - 1;
    if (j1 > w - 1) j1 = w - 1;
    for (Py_ssize_t i = i0; i <= i1; i++)
        for (Py_ssize_t j = j0; j <= j1; j++) {
            double dx = (double)j - *a, dy = (double)i - *b;
            double d = sqrt(dx * dx + dy * dy), e = r - d;
            if (!(fabs(e) < o->edge_band) || !(d > 0.0)) continue;
            double u = e / s, f, fp;
            lookup2(o, u, &f, &fp);
            double cfp = C * (fp / s);
            double res = H[i * w + j] - C * f;
            J[0] = cfp * dx / d; J[1] = cfp * dy / d; J[2] = cfp; J[3] = f; J[4] = 1.0;
            for (int p = 0; p < 5; p++) {
                g[p] += J[p] * res;
                for (int q = 0; q <= p; q++) A[p * 5 + q] += J[p] * J[q];
            }
        }
    for (int p = 0; p < 5; p++)
        for (int q = p + 1; q < 5; q++) A[p * 5 + q] = A[q * 5 + p];
    if (!solve_n(A, g, 5, st) || !isfinite(st[0]) || !isfinite(st[1])) return;
    if (hypot(st[0], st[1]) <= o->edge_max_step) { *a += st[0]; *b += st[1]; }
}

/* One window: G (win*win doubles, bright marker) -> a, b, r, code. Work arrays: T1, T2 of
 * win*win doubles, px/py/dd of 2*win*win doubles, above of win*win bytes. */
static void refine_one(double *G, const RefineOpts *o, double *T1, double *T2, double *px,
                       double *py, double *dd, uint8_t *above, double *oa, double *ob, double *orr,
                       uint8_t *ocode)
{
    const Py_ssize_t w = o->win, nr = o->nring;
    const double cc = (w - 1) / 2.0;
    /* plane least-squares fitted to the border ring, its residual's std = noise */
    double c0 = 0.0, c1 = 0.0, c2 = 0.0;
    for (Py_ssize_t q = 0; q < nr; q++) {
        double v = G[o->ring[q]];
        c0 += v * o->pinv[q]; c1 += v * o->pinv[nr + q]; c2 += v * o->pinv[2 * nr + q];
    }
    double mean = 0.0;
    for (Py_ssize_t q = 0; q < nr; q++) {
        double res = G[o->ring[q]] - (c0 + c1 * o->ring_x[q] + c2 * o->ring_y[q]);
        T1[q] = res; mean += res;
    }
    mean /= (double)nr;
    double var = 0.0;
    for (Py_ssize_t q = 0; q < nr; q++) { double d = T1[q] - mean; var += d * d; }
    double noise = sqrt(var / (double)nr);
    for (Py_ssize_t i = 0; i < w; i++)
        for (Py_ssize_t j = 0; j < w; j++)
            G[i * w + j] -= c0 + c1 * ((double)j - cc) + c2 * ((double)i - cc);
    /* 3x3 binomial smoothing, 'valid' part, in window_fits.smooth3's order */
    const double *H = G;
    Py_ssize_t ws = w, off = 0;
    if (o->smooth) {
        ws = w - 2; off = 1;
        for (Py_ssize_t i = 0; i < w; i++)
            for (Py_ssize_t j = 0; j < ws; j++) {
                const double *g = G + i * w + j;
                double v = g[0] + g[2];
                v += 2.0 * g[1];
                T1[i * ws + j] = v;
            }
        for (Py_ssize_t i = 0; i < ws; i++)
            for (Py_ssize_t j = 0; j < ws; j++) {
                const double *t = T1 + i * ws + j;
                double v = t[0] + t[2 * ws];
                v += 2.0 * t[ws];
                T2[i * ws + j] = v * (1.0 / 16.0);
            }
        H = T2;
    }
    /* maximum with four accumulators (one would wait on each comparison) */
    double pk[4] = {H[0], H[0], H[0], H[0]};
    Py_ssize_t nh = ws * ws, p4 = nh - nh % 4;
    for (Py_ssize_t p = 0; p < p4; p += 4)
        for (int u = 0; u < 4; u++) pk[u] = H[p + u] > pk[u] ? H[p + u] : pk[u];
    for (Py_ssize_t p = p4; p < nh; p++) pk[0] = H[p] > pk[0] ? H[p] : pk[0];
    double peak = pk[0];
    for (int u = 1; u < 4; u++) peak = pk[u] > peak ? pk[u] : peak;
    double L = 0.5 * peak;
    for (Py_ssize_t p = 0; p < ws * ws; p++) above[p] = H[p] > L;
    /* crossings of the level on the grid edges: horizontal neighbours, then vertical */
    Py_ssize_t np_ = 0;
    for (Py_ssize_t i = 0; i < ws; i++)
        for (Py_ssize_t j = 0; j + 1 < ws; j++) {
            Py_ssize_t p = i * ws + j;
            if (above[p] != above[p + 1]) {
                double v0 = H[p];
                px[np_] = (double)j + (v0 - L) / (v0 - H[p + 1]);
                py[np_] = (double)i;
                np_++;
            }
        }
    for (Py_ssize_t i = 0; i + 1 < ws; i++)
        for (Py_ssize_t j = 0; j < ws; j++) {
            Py_ssize_t p = i * ws + j;
            if (above[p] != above[p + ws]) {
                double v0 = H[p];
                px[np_] = (double)j;
                py[np_] = (double)i + (v0 - L) / (v0 - H[p + ws]);
                np_++;
            }
        }
    /* robust circle: fit, drop points beyond max(0.5 px, 3 RMS), fit again */
    Sums s;
    memset(&s, 0, sizeof s);
    for (Py_ssize_t q = 0; q < np_; q++) add_point(&s, px[q], py[q]);
    double a, b, r;
    kasa_solve(&s, &a, &b, &r);
    double sdd = 0.0;
    for (Py_ssize_t q = 0; q < np_; q++) { dd[q] = dist2(px[q], py[q], a, b, r); sdd += dd[q]; }
    double rms = sqrt(sdd / (np_ > 1 ? (double)np_ : 1.0));
    double lim = 9.0 * rms * rms;
    if (lim < 0.25) lim = 0.25;
    memset(&s, 0, sizeof s);
    for (Py_ssize_t q = 0; q < np_; q++)
        if (dd[q] <= lim) add_point(&s, px[q], py[q]);
    double a2, b2, r2;
    kasa_solve(&s, &a2, &b2, &r2);
    sdd = 0.0;
    for (Py_ssize_t q = 0; q < np_; q++)
        if (dd[q] <= lim) sdd += dist2(px[q], py[q], a2, b2, r2);
    rms = sqrt(sdd / (s.S > 1.0 ? s.S : 1.0));
    a2 += off; b2 += off;
    /* reasons, later ones overriding earlier ones as in refine_isocontour */
    int code = OK;
    if (!isfinite(a2) || s.S < o->min_points || rms > o->max_residual
        || hypot(a2 - cc, b2 - cc) > w / 2.0 - 1.0)
        code = FIT_FAILED;
    if (r2 < o->r_min || r2 > o->r_max) code = BAD_RADIUS;
    int touches = 0;
    for (Py_ssize_t j = 0; j < ws && !touches; j++)
        touches = above[j] || above[(ws - 1) * ws + j] || above[j * ws] || above[j * ws + ws - 1];
    if (touches) code = TOUCHES_EDGE;
    if (peak < o->min_contrast || peak < o->min_snr * noise) code = LOW_CONTRAST;
    if (o->edge) edge_step(G, w, &a2, &b2, r2, peak, o);
    *oa = a2; *ob = b2; *orr = r2; *ocode = (uint8_t)code;
}

static PyObject *refine(PyObject *Py_UNUSED(self), PyObject *args)
{
    Py_buffer fb, bfi, bx0, by0, bring, bpinv, bphi, bdphi, ba, bb, br, bc;
    Py_ssize_t nf, h, w, K, win;
    int dark;
    RefineOpts o;
    if (!PyArg_ParseTuple(args, "y*nnny*y*y*nnpy*y*pddddddpddddy*y*w*w*w*w*", &fb, &nf, &h,
                          &w, &bfi, &bx0, &by0, &K, &win, &dark, &bring, &bpinv, &o.smooth,
                          &o.min_contrast, &o.min_snr, &o.r_min, &o.r_max, &o.max_residual,
                          &o.min_points, &o.edge, &o.edge_width, &o.edge_band,
                          &o.edge_max_step, &o.tab_half, &bphi, &bdphi, &ba, &bb, &br, &bc))
        return NULL;
    PyObject *ret = NULL;
    double *work = NULL;
    o.win = win;
    o.nring = bring.len / 8;
    o.ntab = bphi.len / 8;
    o.phi = bphi.buf;
    o.dphi = bdphi.buf;
    o.tab_per_unit = (o.ntab - 1) / (2.0 * o.tab_half);
    if (!need(&fb, nf * h * w, "frames") || !need(&bfi, K * 8, "frame_index")
        || !need(&bx0, K * 8, "x0") || !need(&by0, K * 8, "y0")
        || !need(&bpinv, 3 * o.nring * 8, "pinv") || !need(&ba, K * 8, "a")
        || !need(&bb, K * 8, "b") || !need(&br, K * 8, "r") || !need(&bc, K, "code")
        || !need(&bdphi, o.ntab * 8, "dphi"))
        goto done;
    if (o.ntab < 2 || !(o.tab_half > 0.0) || !(o.edge_width > 0.0)) {
        PyErr_SetString(PyExc_ValueError, "_trackc: bad edge-step table or width");
        goto done;
    }
    const int64_t *fi = bfi.buf, *x0 = bx0.buf, *y0 = by0.buf;
    o.ring = bring.buf;
    o.pinv = bpinv.buf;
    for (Py_ssize_t q = 0; q < o.nring; q++)
        if (o.ring[q] < 0 || o.ring[q] >= win * win) {
            PyErr_SetString(PyExc_ValueError, "_trackc: ring index outside the window");
            goto done;
        }
    for (Py_ssize_t k = 0; k < K; k++)
        if (fi[k] < 0 || fi[k] >= nf || x0[k] < 0 || y0[k] < 0 || x0[k] + win > w
            || y0[k] + win > h) {
            PyErr_Format(PyExc_ValueError, "_trackc: window %zd outside the frames", k);
            goto done;
        }
    Py_ssize_t n = win * win;
    work = malloc(sizeof(double) * (3 * n + 6 * n + 2 * o.nring) + n);
    if (!work) { PyErr_NoMemory(); goto done; }
    {
        double *rx = work + 9 * n, *ry = rx + o.nring;
        for (Py_ssize_t q = 0; q < o.nring; q++) {
            rx[q] = (double)(o.ring[q] % win) - (win - 1) / 2.0;
            ry[q] = (double)(o.ring[q] / win) - (win - 1) / 2.0;
        }
        o.ring_x = rx;
        o.ring_y = ry;
        double *G = work, *T1 = G + n, *T2 = T1 + n, *px = T2 + n, *py = px + 2 * n;
        double *dd = py + 2 * n;
        uint8_t *above = (uint8_t *)(ry + o.nring);
        const uint8_t *frames = fb.buf;
        const int inv = dark ? 255 : 0;
        double *oa = ba.buf, *ob = bb.buf, *orr = br.buf;
        uint8_t *oc = bc.buf;
        Py_BEGIN_ALLOW_THREADS
        double lut[256];  /* grey level -> double (inverted for dark markers) */
        for (int v = 0; v < 256; v++) lut[v] = (double)(v ^ inv);
        for (Py_ssize_t k = 0; k < K; k++) {
            const uint8_t *src = frames + fi[k] * h * w + y0[k] * w + x0[k];
            for (Py_ssize_t i = 0; i < win; i++)
                for (Py_ssize_t j = 0; j < win; j++)
                    G[i * win + j] = lut[src[i * w + j]];
            refine_one(G, &o, T1, T2, px, py, dd, above, oa + k, ob + k, orr + k, oc + k);
        }
        Py_END_ALLOW_THREADS
    }
    ret = Py_NewRef(Py_None);
done:
    free(work);
    PyBuffer_Release(&fb); PyBuffer_Release(&bfi); PyBuffer_Release(&bx0);
    PyBuffer_Release(&by0); PyBuffer_Release(&bring); PyBuffer_Release(&bpinv);
    PyBuffer_Release(&bphi); PyBuffer_Release(&bdphi);
    PyBuffer_Release(&ba); PyBuffer_Release(&bb); PyBuffer_Release(&br); PyBuffer_Release(&bc);
    return ret;
}

static PyMethodDef methods[] = {
    {"seeded", seeded, METH_VARARGS,
     "seeded(frames, nf, h, w, markers, window, dark, min_contrast, max_jump, state, x, y, "
     "reason): the seeded moments pass over nf frames; state (4*markers doubles: x, y, vx, vy) "
     "is updated in place."},
    {"refine", refine, METH_VARARGS,
     "refine(frames, nf, h, w, frame_index, x0, y0, K, window, dark, ring, pinv, smooth, "
     "min_contrast, min_snr, r_min, r_max, max_residual, min_points, edge_step, edge_width, "
     "edge_band, edge_max_step, table_half, phi, dphi, a, b, r, code): the isocontour method "
     "on K windows."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_trackc",
                                    "Compiled kernels of measurement.imaging.tracking.", -1,
                                    methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__trackc(void) { return PyModule_Create(&module); }
