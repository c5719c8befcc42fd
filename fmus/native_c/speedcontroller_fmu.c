/*
 * speedcontroller_fmu.c - the SpeedController model for fmu_core.c: variables (value
 * references as in fmus/speed_controller_slave.py) around pi.c.
 */
#include <math.h>
#include <stdio.h>

#include "fmu_core.h"
#include "pi.h"

#include "abu_guid.h" /* written by fmus/native_build.py: #define ABU_GUID "{...}" */

enum { ZETA, OMEGA_N, J_ABU, THETA_REF_MODE, X_I0, OMEGA_REF, OMEGA, THETA, ALPHA, JERK, TORQUE,
       TORQUE_RATE, TORQUE_ACCEL, X_I, SNAP, CRACKLE, TORQUE_JERK, TORQUE_SNAP, N_VARS };

static const AbuVar VARS[N_VARS] = {
    {"zeta", ABU_REAL, ABU_PARAMETER}, {"omega_n", ABU_REAL, ABU_PARAMETER},
    {"J_abu", ABU_REAL, ABU_PARAMETER}, {"theta_ref_mode", ABU_INTEGER, ABU_PARAMETER},
    {"x_I0", ABU_REAL, ABU_PARAMETER}, {"omega_ref", ABU_REAL, ABU_INPUT},
    {"omega", ABU_REAL, ABU_INPUT}, {"theta", ABU_REAL, ABU_INPUT},
    {"alpha", ABU_REAL, ABU_INPUT}, {"jerk", ABU_REAL, ABU_INPUT},
    {"torque", ABU_REAL, ABU_OUTPUT}, {"torque_rate", ABU_REAL, ABU_OUTPUT},
    {"torque_accel", ABU_REAL, ABU_OUTPUT}, {"x_I", ABU_REAL, ABU_OUTPUT},
    {"snap", ABU_REAL, ABU_INPUT}, {"crackle", ABU_REAL, ABU_INPUT},
    {"torque_jerk", ABU_REAL, ABU_OUTPUT}, {"torque_snap", ABU_REAL, ABU_OUTPUT},
};

/* Inputs in the order of the Python slave's _INPUTS. */
enum { IN_OMEGA_REF, IN_OMEGA, IN_THETA, IN_ALPHA, IN_JERK, IN_SNAP, IN_CRACKLE, N_IN };

typedef struct {
    AbuPI law;
    double x_I0, in[N_IN], time, x_I;
    int initialized;
} Data;

static void defaults(void *data) {
    Data *x = data;
    x->law.zeta = 0.5;
    x->law.omega_n = 2.2;
    x->law.J_abu = 4.5e-5;
    x->law.theta_ref_mode = ABU_THETA_REF_INTEGRAL;
}

static void setup(void *data, double start_time) { ((Data *)data)->time = start_time; }

/* _build_law: the parameters' check, x_I0 included. */
static int law_problem(const Data *x, char *msg, int size) {
    if (abu_pi_check(&x->law, msg, size)) return 1;
    if (isfinite(x->x_I0)) return 0;
    snprintf(msg, (size_t)size, "invalid parameter 'x_I0' = %.17g: expected a finite number [rad]",
             x->x_I0);
    return 1;
}

static int exit_init(void *data, char *msg, int size) {
    Data *x = data;
    if (law_problem(x, msg, size)) return 1;
    x->x_I = x->x_I0;
    x->initialized = 1;
    return 0;
}

static const char *const INPUT_NAMES[N_IN] = {"omega_ref", "omega", "theta", "alpha", "jerk",
                                              "snap", "crackle"};

static int do_step(void *data, double t, double h, char *msg, int size) {
    Data *x = data;
    for (int i = 0; i < N_IN; i++) {
        if (isfinite(x->in[i])) continue;
        snprintf(msg, (size_t)size, "input '%s' = %.17g at t = %.17g s is not finite",
                 INPUT_NAMES[i], x->in[i], t);
        return 1; /* fmi2Discard: nothing advanced */
    }
    x->x_I += abu_pi_integral_increment(h, x->in[IN_OMEGA_REF], x->in[IN_OMEGA],
                                        x->in[IN_ALPHA], x->in[IN_JERK], x->in[IN_SNAP],
                                        x->in[IN_CRACKLE]);
    x->time = t + h;
    return 0;
}

static int input_index(unsigned vr) {
    switch (vr) {
    case OMEGA_REF: return IN_OMEGA_REF;
    case OMEGA: return IN_OMEGA;
    case THETA: return IN_THETA;
    case ALPHA: return IN_ALPHA;
    case JERK: return IN_JERK;
    case SNAP: return IN_SNAP;
    case CRACKLE: return IN_CRACKLE;
    default: return -1;
    }
}

static double get_real(void *data, unsigned vr) {
    const Data *x = data;
    const double *in = x->in;
    char msg[200];
    int i = input_index(vr);
    if (i >= 0) return in[i];
    switch (vr) {
    case ZETA: return x->law.zeta;
    case OMEGA_N: return x->law.omega_n;
    case J_ABU: return x->law.J_abu;
    case X_I0: return x->x_I0;
    case X_I: return x->x_I;
    default: break;
    }
    if (!x->initialized && law_problem(x, msg, sizeof msg)) return NAN;
    switch (vr) {
    case TORQUE:
        return abu_pi_torque(&x->law, x->time, in[IN_OMEGA_REF], in[IN_OMEGA], in[IN_THETA],
                             x->initialized ? x->x_I : x->x_I0);
    case TORQUE_RATE:
        return abu_pi_torque_rate(&x->law, in[IN_OMEGA_REF], in[IN_OMEGA], in[IN_ALPHA]);
    case TORQUE_ACCEL: return abu_pi_torque_derivative(&x->law, in[IN_JERK], in[IN_ALPHA]);
    case TORQUE_JERK: return abu_pi_torque_derivative(&x->law, in[IN_SNAP], in[IN_JERK]);
    default: return abu_pi_torque_derivative(&x->law, in[IN_CRACKLE], in[IN_SNAP]);
    }
}

static int get_int(void *data, unsigned vr) {
    (void)vr; /* theta_ref_mode is the only Integer */
    return ((Data *)data)->law.theta_ref_mode;
}

static void set_real(void *data, unsigned vr, double value) {
    Data *x = data;
    int i = input_index(vr);
    if (i >= 0) x->in[i] = value;
    else if (vr == ZETA) x->law.zeta = value;
    else if (vr == OMEGA_N) x->law.omega_n = value;
    else if (vr == J_ABU) x->law.J_abu = value;
    else if (vr == X_I0) x->x_I0 = value;
}

static void set_int(void *data, unsigned vr, int value) {
    if (vr == THETA_REF_MODE) ((Data *)data)->law.theta_ref_mode = value;
}

static int check(void *data, int initialized, char *msg, int size) {
    Data *x = data;
    double reals[] = {x->law.zeta, x->law.omega_n, x->law.J_abu, x->x_I0, x->time, x->x_I};
    for (int i = 0; i < 6; i++)
        if (!isfinite(reals[i]))
            return snprintf(msg, (size_t)size, "a parameter or the time is not finite"), 1;
    for (int i = 0; i < N_IN; i++)
        if (!isfinite(x->in[i])) return snprintf(msg, (size_t)size, "an input is not finite"), 1;
    if (x->initialized != 0 && x->initialized != 1)
        return snprintf(msg, (size_t)size, "a flag is neither 0 nor 1"), 1;
    if (initialized && !x->initialized)
        return snprintf(msg, (size_t)size, "an initialized instance needs its law"), 1;
    return x->initialized ? law_problem(x, msg, size) : 0;
}

const AbuModel abu_model = {"SpeedController", ABU_GUID, VARS, N_VARS, sizeof(Data), defaults,
                            setup, exit_init, do_step, get_real, get_int, set_real, set_int,
                            check};
