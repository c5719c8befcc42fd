/*
 * staircase_fmu.c - the Staircase model for fmu_core.c: variables (value references as in
 * fmus/staircase_slave.py) around staircase.c. The number of steps taken at the current
 * time is kept with the time, so that reading the outputs solves no root.
 */
#include <math.h>
#include <stdio.h>

#include "fmu_core.h"
#include "staircase.h"

#include "abu_guid.h" /* written by fmus/native_build.py: #define ABU_GUID "{...}" */

#define NO_EVENT 1e30    /* next_event_time when no step is left [s] */
#define EVENT_SNAP 1e-12 /* a step end this close (relative) to a step time lands on it */
#define TWO_PI (2.0 * 3.141592653589793)

enum { OMEGA0, OMEGA_END, T0, TE, STEP, ROUNDING, OMEGA_REF, NEXT_EVENT_TIME, STEP_INDEX,
       N_VARS };

static const AbuVar VARS[N_VARS] = {
    {"omega0", ABU_REAL, ABU_PARAMETER}, {"omega_end", ABU_REAL, ABU_PARAMETER},
    {"t0", ABU_REAL, ABU_PARAMETER}, {"te", ABU_REAL, ABU_PARAMETER},
    {"step", ABU_REAL, ABU_PARAMETER}, {"rounding", ABU_INTEGER, ABU_PARAMETER},
    {"omega_ref", ABU_REAL, ABU_OUTPUT}, {"next_event_time", ABU_REAL, ABU_OUTPUT},
    {"step_index", ABU_INTEGER, ABU_OUTPUT},
};

typedef struct {
    AbuStaircase sc;
    double time;
    int initialized, n, index; /* n steps; index = steps taken at `time` (when initialized) */
} Data;

static void defaults(void *data) {
    Data *x = data;
    x->sc.omega0 = -TWO_PI * 17.0; /* report sec. 4.2.3: -17 Hz -> -22 Hz in 1 s, 1 Hz steps */
    x->sc.omega_end = -TWO_PI * 22.0;
    x->sc.te = 1.0;
    x->sc.step = TWO_PI;
}

static void setup(void *data, double start_time) { ((Data *)data)->time = start_time; }

static int exit_init(void *data, char *msg, int size) {
    Data *x = data;
    if (abu_staircase_check(&x->sc, &x->n, msg, size)) return 1;
    x->index = abu_staircase_index(&x->sc, x->n, x->time);
    x->initialized = 1;
    return 0;
}

/* First step time strictly after the time with `index` steps taken, or +inf. */
static double next_after(const Data *x, int n, int index) {
    return index < n ? abu_staircase_time(&x->sc, n, index + 1) : INFINITY;
}

static int do_step(void *data, double t, double h, char *msg, int size) {
    Data *x = data;
    double end = t + h;
    int at_t = abu_staircase_index_from(&x->sc, x->n, t, x->index);
    double upcoming = next_after(x, x->n, at_t);
    (void)msg; (void)size;
    if (isfinite(upcoming) && fabs(end - upcoming) <= EVENT_SNAP * fmax(1.0, fabs(upcoming)))
        end = upcoming; /* land exactly on the step: the new level is output */
    x->time = end;
    x->index = abu_staircase_index_from(&x->sc, x->n, end, at_t);
    return 0;
}

/* (n, index) now; 0 if the parameters are invalid before initialization. */
static int position(const Data *x, int *n, int *index) {
    char msg[200];
    if (x->initialized) {
        *n = x->n;
        *index = x->index;
        return 1;
    }
    if (abu_staircase_check(&x->sc, n, msg, sizeof msg)) return 0;
    *index = abu_staircase_index(&x->sc, *n, x->time);
    return 1;
}

static double get_real(void *data, unsigned vr) {
    const Data *x = data;
    int n, index;
    double t;
    switch (vr) {
    case OMEGA0: return x->sc.omega0;
    case OMEGA_END: return x->sc.omega_end;
    case T0: return x->sc.t0;
    case TE: return x->sc.te;
    case STEP: return x->sc.step;
    default: break;
    }
    if (!position(x, &n, &index)) return NAN;
    if (vr == OMEGA_REF) return abu_staircase_level(&x->sc, index);
    t = next_after(x, n, index);
    return isinf(t) ? NO_EVENT : t;
}

static int get_int(void *data, unsigned vr) {
    const Data *x = data;
    int n, index;
    if (vr == ROUNDING) return x->sc.rounding;
    return position(x, &n, &index) ? index : -1;
}

static void set_real(void *data, unsigned vr, double value) {
    double *params[] = {&((Data *)data)->sc.omega0, &((Data *)data)->sc.omega_end,
                        &((Data *)data)->sc.t0, &((Data *)data)->sc.te, &((Data *)data)->sc.step};
    if (vr <= STEP) *params[vr] = value;
}

static void set_int(void *data, unsigned vr, int value) {
    if (vr == ROUNDING) ((Data *)data)->sc.rounding = value;
}

static int check(void *data, int initialized, char *msg, int size) {
    Data *x = data;
    double reals[] = {x->sc.omega0, x->sc.omega_end, x->sc.t0, x->sc.te, x->sc.step, x->time};
    for (int i = 0; i < 6; i++)
        if (!isfinite(reals[i]))
            return snprintf(msg, (size_t)size, "a parameter or the time is not finite"), 1;
    if (x->initialized != 0 && x->initialized != 1)
        return snprintf(msg, (size_t)size, "a flag is neither 0 nor 1"), 1;
    if (initialized && !x->initialized)
        return snprintf(msg, (size_t)size, "an initialized instance needs its staircase"), 1;
    if (!x->initialized) return 0;
    if (abu_staircase_check(&x->sc, &x->n, msg, size)) return 1;
    x->index = abu_staircase_index(&x->sc, x->n, x->time); /* derived: never trusted */
    return 0;
}

const AbuModel abu_model = {"Staircase", ABU_GUID, VARS, N_VARS, sizeof(Data), defaults, setup,
                            exit_init, do_step, get_real, get_int, set_real, set_int, check};
