/*
 * staircase.c - see staircase.h; mirrors controller/reference.py (Staircase and
 * _progress_root) operation by operation.
 */
#include "staircase.h"

#include <math.h>
#include <stdio.h>

#include "abu_numerics.h"

#define ABU_PI 3.141592653589793

static double sine_progress(double s) { return s - sin(2.0 * ABU_PI * s) / (2.0 * ABU_PI); }

/* The s in [0, 1] with p(s) = target: safeguarded Newton to a one-ulp bracket. */
static double progress_root(double target) {
    if (target <= 0.0) return 0.0;
    if (target >= 1.0) return 1.0;
    double lo = 0.0, hi = 1.0, s = target;
    for (int i = 0; i < 200; i++) {
        double f = sine_progress(s) - target;
        if (f == 0.0) return s;
        if (f < 0.0) lo = s;
        else hi = s;
        double slope = 1.0 - cos(2.0 * ABU_PI * s);
        double nxt = slope > 0.0 ? s - f / slope : 0.5 * (lo + hi);
        if (!(lo < nxt && nxt < hi)) nxt = 0.5 * (lo + hi);
        if (nxt == s || hi - lo <= abu_ulp(hi)) break;
        s = nxt;
    }
    return fabs(sine_progress(s) - target) <= fabs(sine_progress(lo) - target) ? s : lo;
}

static int bad(char *msg, int size, const char *name, double value, const char *expected) {
    snprintf(msg, (size_t)size, "invalid parameter '%s' = %.17g: expected %s", name, value,
             expected);
    return 1;
}

int abu_staircase_check(const AbuStaircase *s, int *n, char *msg, int size) {
    const char *names[5] = {"omega0", "omega_end", "t0", "te", "step"};
    double values[5] = {s->omega0, s->omega_end, s->t0, s->te, s->step};
    for (int i = 0; i < 5; i++)
        if (!isfinite(values[i])) return bad(msg, size, names[i], values[i], "a finite number");
    if (s->te <= 0.0) return bad(msg, size, "te", s->te, "a duration > 0 s");
    if (s->step <= 0.0) return bad(msg, size, "step", s->step, "a setpoint step > 0 rad/s");
    if (s->rounding < 0 || s->rounding > 2) {
        snprintf(msg, (size_t)size, "invalid parameter 'rounding' = %d: expected 0 (lead), "
                 "1 (nearest) or 2 (trail)", s->rounding);
        return 1;
    }
    double ratio = fabs(s->omega_end - s->omega0) / s->step + 1e-9;
    int count = ratio <= ABU_STAIRCASE_MAX_STEPS + 1 ? (int)floor(ratio)
                                                     : ABU_STAIRCASE_MAX_STEPS + 1;
    if (count < 1)
        return bad(msg, size, "omega_end", s->omega_end, "a value at least one step away from "
                   "omega0 (the staircase has no step)");
    if (count > ABU_STAIRCASE_MAX_STEPS)
        return bad(msg, size, "step", s->step, "a setpoint step giving at most 100000 steps");
    *n = count;
    return 0;
}

double abu_staircase_time(const AbuStaircase *s, int n, int k) {
    static const double offsets[3] = {1.0, 0.5, 0.0};
    double span = fabs(s->omega_end - s->omega0);
    (void)n;
    return s->t0 + s->te * progress_root((k - offsets[s->rounding]) * s->step / span);
}

double abu_staircase_level(const AbuStaircase *s, int k) {
    double direction = copysign(1.0, s->omega_end - s->omega0);
    return s->omega0 + direction * k * s->step;
}

int abu_staircase_index(const AbuStaircase *s, int n, double t) {
    int lo = 0, hi = n; /* bisect_right: the first k with time(k + 1) > t */
    while (lo < hi) {
        int mid = lo + (hi - lo) / 2;
        if (t < abu_staircase_time(s, n, mid + 1)) hi = mid;
        else lo = mid + 1;
    }
    return lo;
}

int abu_staircase_index_from(const AbuStaircase *s, int n, double t, int hint) {
    if (hint < 0 || hint > n) return abu_staircase_index(s, n, t);
    for (int walked = 0; walked < 8; walked++) {
        if (hint < n && abu_staircase_time(s, n, hint + 1) <= t) hint++;
        else if (hint > 0 && abu_staircase_time(s, n, hint) > t) hint--;
        else return hint;
    }
    return abu_staircase_index(s, n, t); /* moved by many steps: bisect */
}
