/*
 * abuball_fmu.c - the AbuBall model for fmu_core.c: variables (value references as in
 * fmus/abu_ball_slave.py), start values, outputs and do_step around abu_plant.c.
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "abu_plant.h"
#include "fmu_core.h"

#include "abu_guid.h" /* written by fmus/native_build.py: #define ABU_GUID "{...}" */

#define NO_SWITCH -1e30 /* switch times when there is none */

enum { M, D, L, MU, MU_D, J_ABU, TAU_MOTOR, BALL_REACTION, THETA0, OMEGA0, BETA0, BETA_DOT0,
       TORQUE, TORQUE_RATE, THETA, OMEGA, ALPHA, BETA, BETA_DOT, BETA_DDOT, NORMAL_FORCE,
       FRICTION_FORCE, MU_REQ, TORQUE_APPLIED, JERK, MODE, SWITCH_COUNT, T_LAST_SWITCH,
       STEP_SWITCHES, T_FIRST_STEP_SWITCH, TORQUE_ACCEL, TORQUE_JERK, TORQUE_SNAP, SNAP,
       CRACKLE, MU_REQ_PEAK, N_VARS };

static const AbuVar VARS[N_VARS] = {
    {"m", ABU_REAL, ABU_PARAMETER}, {"d", ABU_REAL, ABU_PARAMETER},
    {"l", ABU_REAL, ABU_PARAMETER}, {"mu", ABU_REAL, ABU_PARAMETER},
    {"mu_d", ABU_REAL, ABU_PARAMETER}, {"J_abu", ABU_REAL, ABU_PARAMETER},
    {"tau_motor", ABU_REAL, ABU_PARAMETER}, {"ball_reaction", ABU_BOOLEAN, ABU_PARAMETER},
    {"theta0", ABU_REAL, ABU_PARAMETER}, {"omega0", ABU_REAL, ABU_PARAMETER},
    {"beta0", ABU_REAL, ABU_PARAMETER}, {"beta_dot0", ABU_REAL, ABU_PARAMETER},
    {"torque", ABU_REAL, ABU_INPUT}, {"torque_rate", ABU_REAL, ABU_INPUT},
    {"theta", ABU_REAL, ABU_OUTPUT}, {"omega", ABU_REAL, ABU_OUTPUT},
    {"alpha", ABU_REAL, ABU_OUTPUT}, {"beta", ABU_REAL, ABU_OUTPUT},
    {"beta_dot", ABU_REAL, ABU_OUTPUT}, {"beta_ddot", ABU_REAL, ABU_OUTPUT},
    {"normal_force", ABU_REAL, ABU_OUTPUT}, {"friction_force", ABU_REAL, ABU_OUTPUT},
    {"mu_req", ABU_REAL, ABU_OUTPUT}, {"torque_applied", ABU_REAL, ABU_OUTPUT},
    {"jerk", ABU_REAL, ABU_OUTPUT}, {"mode", ABU_INTEGER, ABU_OUTPUT},
    {"switch_count", ABU_INTEGER, ABU_OUTPUT}, {"t_last_switch", ABU_REAL, ABU_OUTPUT},
    {"step_switches", ABU_INTEGER, ABU_OUTPUT}, {"t_first_step_switch", ABU_REAL, ABU_OUTPUT},
    {"torque_accel", ABU_REAL, ABU_INPUT}, {"torque_jerk", ABU_REAL, ABU_INPUT},
    {"torque_snap", ABU_REAL, ABU_INPUT}, {"snap", ABU_REAL, ABU_OUTPUT},
    {"crackle", ABU_REAL, ABU_OUTPUT}, {"mu_req_peak", ABU_REAL, ABU_OUTPUT},
};

typedef struct {
    AbuParams p;
    double theta0, omega0, beta0, beta_dot0;
    double in[5]; /* torque, torque_rate, torque_accel, torque_jerk, torque_snap */
    double start_time, t_first_step_switch, step_peak;
    int step_switches, initialized;
    AbuPlant plant; /* valid when initialized; plant.p is a copy of p */
} Data;

static void defaults(void *data) {
    Data *x = data;
    x->p.m = 1.4e-4; x->p.d = 3.0e-3; x->p.l = 1.15e-2; x->p.mu = 2.75e-3; x->p.mu_d = -1.0;
    x->p.J_abu = 4.5e-5; x->p.tau_motor = 0.0; x->p.ball_reaction = 0;
    x->omega0 = -2.0 * 3.141592653589793 * 17.0; /* the report's experiment starts at -17 Hz */
    x->t_first_step_switch = NO_SWITCH;
}

static void setup(void *data, double start_time) { ((Data *)data)->start_time = start_time; }

static int input_index(unsigned vr) {
    switch (vr) {
    case TORQUE: return 0;
    case TORQUE_RATE: return 1;
    case TORQUE_ACCEL: return 2;
    case TORQUE_JERK: return 3;
    case TORQUE_SNAP: return 4;
    default: return -1;
    }
}

/* A plant from the parameters and start values (_new_plant); 0 if they are invalid. */
static int new_plant(const Data *x, AbuPlant *pl, char *msg, int size) {
    if (abu_params_check(&x->p, msg, size)) return 0;
    memset(pl, 0, sizeof *pl);
    pl->p = x->p;
    pl->s.time = x->start_time;
    pl->s.theta = x->theta0;
    pl->s.omega = x->omega0;
    pl->s.beta = x->beta0;
    pl->s.beta_dot = x->beta_dot0;
    pl->s.torque_applied = x->in[0];
    pl->s.mode = x->beta_dot0 == 0.0 ? ABU_STICK : (x->beta_dot0 > 0.0 ? 1 : -1);
    pl->s.t_last_switch = -INFINITY;
    return 1;
}

/* The plant; before initialization one built from the current parameters (NULL if bad). */
static const AbuPlant *current(const Data *x, AbuPlant *scratch) {
    char msg[300];
    if (x->initialized) return &x->plant;
    return new_plant(x, scratch, msg, sizeof msg) ? scratch : NULL;
}

static int exit_init(void *data, char *msg, int size) {
    Data *x = data;
    if (!new_plant(x, &x->plant, msg, size)) return 1;
    x->initialized = 1;
    x->step_switches = 0;
    x->t_first_step_switch = NO_SWITCH;
    x->step_peak = 0.0;
    return 0;
}

static int do_step(void *data, double t, double h, char *msg, int size) {
    Data *x = data;
    char why[400];
    int n;
    double first = NO_SWITCH;
    for (int i = 0; i < 5; i++) {
        if (isfinite(x->in[i])) continue;
        snprintf(msg, (size_t)size, "input '%s' = %.17g at t = %.17g s is not finite",
                 VARS[i == 0 ? TORQUE : i == 1 ? TORQUE_RATE : TORQUE_ACCEL + i - 2].name,
                 x->in[i], t);
        return 1;
    }
    AbuPlantState saved = x->plant.s;
    x->plant.s.time = t; /* follow the master's clock through rounding */
    if (abu_plant_advance(&x->plant, h, x->in, &n, &first, why, sizeof why)) {
        x->plant.s = saved; /* fmi2Discard: nothing advanced */
        snprintf(msg, (size_t)size, "step [%.17g, %.17g] s failed: SimulationError: %s", t,
                 t + h, why);
        return 1;
    }
    x->step_switches = n;
    x->t_first_step_switch = n > 0 ? first : NO_SWITCH;
    x->step_peak = x->plant.step_peak;
    return 0;
}

static double alpha_derivative(const Data *x, const AbuPlant *pl, int order) {
    double out[5];
    abu_alpha_taylor(&pl->p, x->in, order + 1, abu_applied_torque(pl, x->in[0]), pl->s.omega,
                     pl->s.beta_dot, pl->s.mode, order, out);
    return out[order];
}

static double get_output(const Data *x, unsigned vr) {
    AbuPlant scratch;
    AbuOutputs o;
    const AbuPlant *pl = current(x, &scratch);
    if (pl == NULL) return NAN;
    switch (vr) {
    case THETA: return pl->s.theta;
    case OMEGA: return pl->s.omega;
    case BETA: return pl->s.beta;
    case BETA_DOT: return pl->s.beta_dot;
    case TORQUE_APPLIED: return abu_applied_torque(pl, x->in[0]);
    case T_LAST_SWITCH: return pl->s.t_last_switch == -INFINITY ? NO_SWITCH : pl->s.t_last_switch;
    case JERK: return alpha_derivative(x, pl, 1);
    case SNAP: return alpha_derivative(x, pl, 2);
    case CRACKLE: return alpha_derivative(x, pl, 3);
    default: break;
    }
    abu_plant_outputs(pl, x->in[0], &o);
    switch (vr) {
    case ALPHA: return o.alpha;
    case BETA_DDOT: return o.beta_ddot;
    case NORMAL_FORCE: return o.normal_force;
    case FRICTION_FORCE: return o.friction_force;
    default: return o.mu_req;
    }
}

static double get_real(void *data, unsigned vr) {
    const Data *x = data;
    int i = input_index(vr);
    if (i >= 0) return x->in[i];
    switch (vr) {
    case M: return x->p.m;
    case D: return x->p.d;
    case L: return x->p.l;
    case MU: return x->p.mu;
    case MU_D: return x->p.mu_d;
    case J_ABU: return x->p.J_abu;
    case TAU_MOTOR: return x->p.tau_motor;
    case THETA0: return x->theta0;
    case OMEGA0: return x->omega0;
    case BETA0: return x->beta0;
    case BETA_DOT0: return x->beta_dot0;
    case T_FIRST_STEP_SWITCH: return x->t_first_step_switch;
    case MU_REQ_PEAK: return x->step_peak;
    default: return get_output(x, vr);
    }
}

static int get_int(void *data, unsigned vr) {
    const Data *x = data;
    AbuPlant scratch;
    const AbuPlant *pl;
    if (vr == BALL_REACTION) return x->p.ball_reaction;
    if (vr == STEP_SWITCHES) return x->step_switches;
    pl = current(x, &scratch);
    if (pl == NULL) return 0;
    return vr == MODE ? pl->s.mode : pl->s.switch_count;
}

static void set_real(void *data, unsigned vr, double value) {
    Data *x = data;
    double *params[] = {&x->p.m, &x->p.d, &x->p.l, &x->p.mu, &x->p.mu_d, &x->p.J_abu,
                        &x->p.tau_motor, NULL, &x->theta0, &x->omega0, &x->beta0,
                        &x->beta_dot0};
    int i = input_index(vr);
    if (i >= 0) x->in[i] = value;
    else if (vr < BALL_REACTION || (vr > BALL_REACTION && vr <= BETA_DOT0)) *params[vr] = value;
}

static void set_int(void *data, unsigned vr, int value) {
    if (vr == BALL_REACTION) ((Data *)data)->p.ball_reaction = value != 0;
}

static int not_finite(const double *v, int n) {
    for (int i = 0; i < n; i++)
        if (!isfinite(v[i])) return 1;
    return 0;
}

static int check(void *data, int initialized, char *msg, int size) {
    Data *x = data;
    const AbuPlantState *s = &x->plant.s;
    double reals[] = {x->p.m, x->p.d, x->p.l, x->p.mu, x->p.mu_d, x->p.J_abu, x->p.tau_motor,
                      x->theta0, x->omega0, x->beta0, x->beta_dot0, x->in[0], x->in[1],
                      x->in[2], x->in[3], x->in[4], x->start_time, x->t_first_step_switch,
                      x->step_peak};
    if (not_finite(reals, (int)(sizeof reals / sizeof reals[0])))
        return snprintf(msg, (size_t)size, "a parameter, input or step output is not finite"), 1;
    if ((x->p.ball_reaction != 0 && x->p.ball_reaction != 1)
        || (x->initialized != 0 && x->initialized != 1))
        return snprintf(msg, (size_t)size, "a flag is neither 0 nor 1"), 1;
    if (initialized && !x->initialized)
        return snprintf(msg, (size_t)size, "an initialized instance needs its plant state"), 1;
    if (!x->initialized) return 0;
    double plant[] = {s->time, s->theta, s->omega, s->beta, s->beta_dot, s->torque_applied,
                      x->plant.step_peak};
    if (not_finite(plant, 7) || isnan(s->t_last_switch) || s->t_last_switch == INFINITY)
        return snprintf(msg, (size_t)size, "the plant state is not finite"), 1;
    if (s->mode < -1 || s->mode > 1 || s->switch_count < 0)
        return snprintf(msg, (size_t)size, "bad mode or switch bookkeeping"), 1;
    if (abu_params_check(&x->p, msg, size)) return 1;
    x->plant.p = x->p; /* the plant runs on the state's parameters */
    return 0;
}

const AbuModel abu_model = {"AbuBall", ABU_GUID, VARS, N_VARS, sizeof(Data), defaults, setup,
                            exit_init, do_step, get_real, get_int, set_real, set_int, check};
