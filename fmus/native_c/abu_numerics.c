/*
 * abu_numerics.c - see abu_numerics.h. Each function mirrors the one of the same name in
 * abu_model/numerics.py; comments there explain the algorithms, comments here only where
 * C differs (Python's min/max keep the first argument on ties and NaN, so do these).
 */
#include "abu_numerics.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

/* Python's min(a, b) / max(a, b): b only if strictly smaller / larger. */
static double py_min(double a, double b) { return b < a ? b : a; }
static double py_max(double a, double b) { return b > a ? b : a; }

/* math.ulp */
double abu_ulp(double x) {
    x = fabs(x);
    if (isnan(x) || isinf(x)) return x;
    double up = nextafter(x, INFINITY);
    if (isinf(up)) return x - nextafter(x, -INFINITY);
    return up - x;
}

double abu_poly_eval(const double *c, int n, double x) {
    double value = 0.0;
    for (int i = n - 1; i >= 0; i--) value = value * x + c[i];
    return value;
}

int abu_poly_der(const double *c, int n, double *out) {
    for (int i = 1; i < n; i++) out[i - 1] = i * c[i];
    return n > 0 ? n - 1 : 0;
}

void abu_poly_shift(const double *c, int n, double x0, double *out) {
    memmove(out, c, (size_t)n * sizeof *out);
    if (x0 == 0.0) return;
    for (int i = 0; i < n - 1; i++)
        for (int j = n - 2; j >= i; j--) out[j] += x0 * out[j + 1];
}

int abu_poly_mul(const double *a, int na, const double *b, int nb, double *out) {
    int n = na + nb - 1;
    for (int i = 0; i < n; i++) out[i] = 0.0;
    for (int i = 0; i < na; i++)
        for (int j = 0; j < nb; j++) out[i + j] += a[i] * b[j];
    return n;
}

int abu_poly_int(const double *c, int n, double c0, double *out) {
    double tmp[ABU_MAXC];
    for (int i = 0; i < n; i++) tmp[i] = c[i] / (i + 1);
    out[0] = c0;
    for (int i = 0; i < n; i++) out[i + 1] = tmp[i];
    return n + 1;
}

static int trim(const double *c, int n, double *out) {
    while (n > 0 && c[n - 1] == 0.0) n--;
    memmove(out, c, (size_t)n * sizeof *out);
    return n;
}

double abu_brent_root(abu_fn f, void *ctx, double a, double b, double fa, double fb) {
    if (fa == 0.0) return a;
    if (fb == 0.0) return b;
    double width = fabs(b - a);
    for (int it = 0; it < 200; it++) {
        double x = fb != fa ? b - fb * (b - a) / (fb - fa) : 0.5 * (a + b);
        double lo = a < b ? a : b, hi = a < b ? b : a;
        if (!(lo < x && x < hi) || fabs(b - a) > 0.5 * width)
            x = 0.5 * (a + b); /* bisect: the secant left the bracket or stalls */
        width = fabs(b - a);
        if (x == a || x == b) break;
        double fx = f(ctx, x);
        if (fx == 0.0) return x;
        if ((fx < 0.0) == (fa < 0.0)) { a = x; fa = fx; }
        else { b = x; fb = fx; }
        if (fabs(b - a) <= 2.0 * abu_ulp(py_max(fabs(a), fabs(b)))) break;
    }
    return fabs(fa) < fabs(fb) ? a : b;
}

typedef struct { const double *c; int n; } PolyCtx;
static double poly_fn(void *ctx, double x) {
    const PolyCtx *p = ctx;
    return abu_poly_eval(p->c, p->n, x);
}

/* Sorted real roots in (lo, hi) at sign changes (recursive on the derivative). */
static int real_roots(const double *c_in, int n_in, double lo, double hi, double *roots) {
    double c[ABU_MAXC], d[ABU_MAXC], points[ABU_MAXC + 2];
    int n = trim(c_in, n_in, c);
    if (n <= 1) return 0;
    if (n == 2) {
        double x = -c[0] / c[1];
        if (lo < x && x < hi) { roots[0] = x; return 1; }
        return 0;
    }
    int nd = abu_poly_der(c, n, d);
    points[0] = lo;
    int np = 1 + real_roots(d, nd, lo, hi, points + 1);
    points[np++] = hi;
    PolyCtx ctx = {c, n};
    int count = 0;
    for (int i = 0; i + 1 < np; i++) {
        double a = points[i], b = points[i + 1];
        double fa = abu_poly_eval(c, n, a), fb = abu_poly_eval(c, n, b);
        if ((fa < 0.0) != (fb < 0.0) && b > a) {
            double x = abu_brent_root(poly_fn, &ctx, a, b, fa, fb);
            if (lo < x && x < hi) roots[count++] = x;
        }
    }
    return count;
}

int abu_poly_first_negative(const double *c_in, int n_in, double span, double end_tolerance,
                            double *u) {
    double c[ABU_MAXC], points[ABU_MAXC + 2];
    int n = trim(c_in, n_in, c);
    if (n == 0) return 0;
    if (c[0] < 0.0) { *u = 0.0; return 1; }
    if (n == 1) return 0;
    double limit = span + end_tolerance;
    /* Cheap bound: on [0, limit] c(u) >= c0 + sum of the negative terms at u = limit. */
    double bound = c[0], power = 1.0;
    for (int i = 1; i < n; i++) {
        power *= limit;
        if (c[i] < 0.0) bound += c[i] * power;
    }
    if (bound > 0.0) return 0;
    points[0] = 0.0;
    int np = 1 + real_roots(c, n, 0.0, limit, points + 1);
    points[np++] = limit;
    for (int i = 0; i + 1 < np; i++) {
        double a = points[i], b = points[i + 1];
        if (b > a && abu_poly_eval(c, n, 0.5 * (a + b)) < 0.0) {
            *u = py_min(a, span);
            return 1;
        }
    }
    return 0;
}

/* Dormand-Prince 5(4) tableau (the values of the Python tuples, rounded the same way). */
static const double C1 = 1.0 / 5, C2 = 3.0 / 10, C3 = 4.0 / 5, C4 = 8.0 / 9;
static const double A10 = 1.0 / 5;
static const double A20 = 3.0 / 40, A21 = 9.0 / 40;
static const double A30 = 44.0 / 45, A31 = -56.0 / 15, A32 = 32.0 / 9;
static const double A40 = 19372.0 / 6561, A41 = -25360.0 / 2187, A42 = 64448.0 / 6561,
                    A43 = -212.0 / 729;
static const double A50 = 9017.0 / 3168, A51 = -355.0 / 33, A52 = 46732.0 / 5247,
                    A53 = 49.0 / 176, A54 = -5103.0 / 18656;
static const double B0 = 35.0 / 384, B2 = 500.0 / 1113, B3 = 125.0 / 192, B4 = -2187.0 / 6784,
                    B5 = 11.0 / 84;
static const double E0 = -71.0 / 57600, E2 = 71.0 / 16695, E3 = -71.0 / 1920,
                    E4 = 17253.0 / 339200, E5 = -22.0 / 525, E6 = 1.0 / 40;

void abu_rk45_step(abu_rhs f, void *ctx, double t, const double *y, double h,
                   const double *k0, double *y_new, double *err, double *k7) {
    double k1[ABU_NY], k2[ABU_NY], k3[ABU_NY], k4[ABU_NY], k5[ABU_NY], k6[ABU_NY], s[ABU_NY];
    int j;
    if (k0 == NULL) f(ctx, t, y, k1);
    else memcpy(k1, k0, sizeof k1);
    for (j = 0; j < ABU_NY; j++) s[j] = y[j] + h * A10 * k1[j];
    f(ctx, t + C1 * h, s, k2);
    for (j = 0; j < ABU_NY; j++) s[j] = y[j] + h * (A20 * k1[j] + A21 * k2[j]);
    f(ctx, t + C2 * h, s, k3);
    for (j = 0; j < ABU_NY; j++) s[j] = y[j] + h * (A30 * k1[j] + A31 * k2[j] + A32 * k3[j]);
    f(ctx, t + C3 * h, s, k4);
    for (j = 0; j < ABU_NY; j++)
        s[j] = y[j] + h * (A40 * k1[j] + A41 * k2[j] + A42 * k3[j] + A43 * k4[j]);
    f(ctx, t + C4 * h, s, k5);
    for (j = 0; j < ABU_NY; j++)
        s[j] = y[j] + h * (A50 * k1[j] + A51 * k2[j] + A52 * k3[j] + A53 * k4[j] + A54 * k5[j]);
    f(ctx, t + h, s, k6);
    double yn[ABU_NY];
    for (j = 0; j < ABU_NY; j++)
        yn[j] = y[j] + h * (B0 * k1[j] + B2 * k3[j] + B3 * k4[j] + B4 * k5[j] + B5 * k6[j]);
    double k[ABU_NY];
    f(ctx, t + h, yn, k);
    if (err != NULL)
        for (j = 0; j < ABU_NY; j++)
            err[j] = h * (E0 * k1[j] + E2 * k3[j] + E3 * k4[j] + E4 * k5[j] + E5 * k6[j]
                          + E6 * k[j]);
    memcpy(y_new, yn, sizeof yn);
    if (k7 != NULL) memcpy(k7, k, sizeof k);
}

/* Python's max over the generator: the first value, replaced only by a larger one. */
static double error_norm(const double *err, const double *y0, const double *y1, double rtol,
                         const double *atol) {
    double norm = 0.0;
    for (int j = 0; j < ABU_NY; j++) {
        double v = fabs(err[j]) / (atol[j] + rtol * py_max(fabs(y0[j]), fabs(y1[j])));
        if (j == 0 || v > norm) norm = v;
    }
    return norm;
}

typedef struct {
    abu_rhs f; void *ctx; double t; const double *y; const double *k; int index; double sign;
} EventCtx;

/* The event at the end of one RK step of length `step` from the last accepted point. */
static double event_after(void *p, double step) {
    const EventCtx *e = p;
    double yn[ABU_NY];
    abu_rk45_step(e->f, e->ctx, e->t, e->y, step, e->k, yn, NULL, NULL);
    return e->sign * yn[e->index];
}

int abu_integrate_until(abu_rhs f, void *ctx, double t0, const double *y0, double t_end,
                        double rtol, const double *atol, int event_index, double event_sign,
                        double *t_out, double *y_out, char *problem, int problem_size) {
    double t = t0, y[ABU_NY], k[ABU_NY], y_new[ABU_NY], err[ABU_NY], k_new[ABU_NY];
    memcpy(y, y0, sizeof y);
    f(ctx, t, y, k);
    double h = t_end - t0;
    double g_prev = event_sign * y[event_index];
    /* slope of an event that starts at 0 and rises (rising_on = 0: nothing to guard) */
    double rising = g_prev == 0.0 ? event_sign * k[event_index] : 0.0;
    int rising_on = g_prev == 0.0 && rising > 0.0;
    for (int steps = 0; steps < 100000; steps++) {
        if (t >= t_end) {
            *t_out = t_end;
            memcpy(y_out, y, sizeof y);
            return 0;
        }
        h = py_min(h, t_end - t);
        abu_rk45_step(f, ctx, t, y, h, k, y_new, err, k_new);
        double norm = error_norm(err, y, y_new, rtol, atol);
        if (!isfinite(norm)) {
            h *= 0.2;
            if (h <= 1e-18) {
                snprintf(problem, (size_t)problem_size, "non-finite derivative at t = %.17g", t);
                return -1;
            }
            continue;
        }
        if (norm > 1.0) {
            h *= py_max(0.2, 0.9 * pow(norm, -0.2));
            if (h <= 4.0 * abu_ulp(py_max(fabs(t), 1.0))) {
                snprintf(problem, (size_t)problem_size, "step size underflow at t = %.17g", t);
                return -1;
            }
            continue;
        }
        double g_new = event_sign * y_new[event_index];
        if (rising_on) {
            if (g_new <= 0.0 && h > 64.0 * abu_ulp(py_max(fabs(t), 1.0))) {
                double curvature = (g_new - rising * h) / (h * h);
                h = py_min(0.5 * h, -0.5 * rising / curvature);
                continue;
            }
            rising_on = 0; /* the event is above 0 at the end of this step */
        }
        if (g_prev > 0.0 && g_new <= 0.0) {
            EventCtx e = {f, ctx, t, y, k, event_index, event_sign};
            double step = abu_brent_root(event_after, &e, 0.0, h, g_prev, g_new);
            if (step <= 0.0) {
                *t_out = t;
                memcpy(y_out, y, sizeof y);
                return 1;
            }
            *t_out = t + step;
            abu_rk45_step(f, ctx, t, y, step, k, y_out, NULL, NULL);
            return 1;
        }
        g_prev = g_new;
        t = h == t_end - t ? t_end : t + h;
        memcpy(y, y_new, sizeof y);
        memcpy(k, k_new, sizeof k);
        h *= norm > 0.0 ? py_min(5.0, 0.9 * pow(norm, -0.2)) : 5.0;
    }
    snprintf(problem, (size_t)problem_size, "more than 100000 integration steps");
    return -1;
}
