/*
 * abu_plant.c - see abu_plant.h. Mirrors abu_model/dynamics.py and abu_model/plant.py
 * function by function (same names without the leading underscore) and operation by
 * operation: the native AbuBall must give the Python FMU's switch times to the last bits,
 * so expressions keep Python's order of evaluation (and pow where Python writes **).
 */
#include "abu_plant.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#include "abu_numerics.h"

static double py_max(double a, double b) { return b > a ? b : a; }

/* ------------------------------------------------------------------ parameters */
static int bad(char *msg, int size, const char *name, double value, const char *expected) {
    snprintf(msg, (size_t)size, "invalid parameter '%s' = %.17g: expected %s", name, value,
             expected);
    return 1;
}

int abu_params_check(const AbuParams *p, char *msg, int size) {
    if (!(isfinite(p->m) && p->m > 0.0)) return bad(msg, size, "m", p->m, "a finite number > 0 kg");
    if (!(isfinite(p->d) && p->d > 0.0)) return bad(msg, size, "d", p->d, "a finite number > 0 m");
    if (!(isfinite(p->l) && p->l > 0.0)) return bad(msg, size, "l", p->l, "a finite number > 0 m");
    if (p->d >= 2.0 * p->l) return bad(msg, size, "d", p->d, "a diameter < 2 l");
    if (!(isfinite(p->mu) && p->mu >= 0.0))
        return bad(msg, size, "mu", p->mu, "a finite number >= 0");
    if (!(isfinite(p->mu_d) && p->mu_d < 0.0)) { /* a negative mu_d means mu_d = mu */
        if (!(isfinite(p->mu_d) && p->mu_d >= 0.0))
            return bad(msg, size, "mu_d", p->mu_d, "a finite number >= 0");
        if (p->mu_d > p->mu)
            return bad(msg, size, "mu_d", p->mu_d, "a value <= mu (sliding friction above "
                       "static friction leaves the stick/slip transition without a consistent "
                       "solution)");
    }
    if (!(isfinite(p->J_abu) && p->J_abu > 0.0))
        return bad(msg, size, "J_abu", p->J_abu, "a finite number > 0 kg m^2");
    if (!(isfinite(p->tau_motor) && p->tau_motor >= 0.0))
        return bad(msg, size, "tau_motor", p->tau_motor, "a finite number >= 0 s");
    return 0;
}

double abu_mu_dynamic(const AbuParams *p) { return p->mu_d < 0.0 ? p->mu : p->mu_d; }

static double ball_J(const AbuParams *p) { return p->m * pow(p->d, 2) / 10.0; }
static double M_bb(const AbuParams *p) {
    return p->m * pow(p->l, 2) + ball_J(p) * pow(2.0 * p->l / p->d, 2);
}
static double coupling(const AbuParams *p) {
    return p->m * pow(p->l, 2) - ball_J(p) * 2.0 * p->l / p->d;
}
static double lever_ratio(const AbuParams *p) { return (p->l - p->d / 5.0) / p->l; }

double abu_J_total(const AbuParams *p) {
    return p->J_abu + (p->ball_reaction ? p->m * pow(p->l, 2) + ball_J(p) : 0.0);
}

/* ------------------------------------------------------------------ dynamics */
static double normal_force(const AbuParams *p, double omega, double beta_dot) {
    return p->m * (p->l * pow(omega + beta_dot, 2) + 0.4 * p->l * pow(beta_dot, 2)
                   - 0.2 * p->d * omega * beta_dot);
}

static double stick_friction(const AbuParams *p, double alpha) {
    return -coupling(p) * alpha / p->l;
}

static double mu_required(const AbuParams *p, double alpha, double omega) {
    if (omega == 0.0) return alpha != 0.0 ? INFINITY : 0.0;
    return lever_ratio(p) * fabs(alpha) / (omega * omega);
}

static double stick_alpha(const AbuParams *p, double torque) { return torque / abu_J_total(p); }

static int stick_holds(const AbuParams *p, double torque, double omega) {
    double f_w = stick_friction(p, stick_alpha(p, torque));
    return fabs(f_w) <= p->mu * normal_force(p, omega, 0.0) * (1.0 + 1e-12);
}

static int slip_direction(const AbuParams *p, double torque) {
    return stick_friction(p, stick_alpha(p, torque)) > 0.0 ? 1 : -1;
}

/* (a_t, a_w, b_t, b_w): alpha = a_t T + a_w F_w, beta'' = b_t T + b_w F_w in slip. */
static void slip_gains(const AbuParams *p, double g[4]) {
    double c = coupling(p), M = M_bb(p), l = p->l;
    if (p->ball_reaction) {
        double J_tot = abu_J_total(p), det = J_tot * M - c * c;
        g[0] = M / det; g[1] = c * l / det; g[2] = -c / det; g[3] = -J_tot * l / det;
    } else {
        g[0] = 1.0 / p->J_abu; g[1] = 0.0; g[2] = -c / (M * p->J_abu); g[3] = -l / M;
    }
}

static void accelerations(const AbuParams *p, double torque, double omega, double beta_dot,
                          int mode, AbuOutputs *out) {
    if (mode == ABU_STICK) {
        double alpha = stick_alpha(p, torque);
        out->alpha = alpha;
        out->beta_ddot = 0.0;
        out->normal_force = normal_force(p, omega, 0.0);
        out->friction_force = stick_friction(p, alpha);
        return;
    }
    double f_n = normal_force(p, omega, beta_dot);
    double f_w = abu_mu_dynamic(p) * f_n * mode;
    double c = coupling(p), M = M_bb(p), l = p->l;
    if (p->ball_reaction) {
        double J_tot = abu_J_total(p), det = J_tot * M - c * c;
        out->alpha = (M * torque + c * l * f_w) / det;
        out->beta_ddot = (-J_tot * l * f_w - c * torque) / det;
    } else {
        out->alpha = torque / p->J_abu;
        out->beta_ddot = -(c * out->alpha + l * f_w) / M;
    }
    out->normal_force = f_n;
    out->friction_force = f_w;
}

double abu_applied_torque(const AbuPlant *pl, double torque) {
    return pl->p.tau_motor == 0.0 ? torque : pl->s.torque_applied;
}

void abu_plant_outputs(const AbuPlant *pl, double torque, AbuOutputs *out) {
    accelerations(&pl->p, abu_applied_torque(pl, torque), pl->s.omega, pl->s.beta_dot,
                  pl->s.mode, out);
    out->mu_req = mu_required(&pl->p, out->alpha, pl->s.omega);
}

void abu_alpha_taylor(const AbuParams *p, const double *td, int nd, double applied,
                      double omega, double beta_dot, int mode, int order, double *out) {
    double tm = p->tau_motor, fact[7], T[6], Ta[6], w[7] = {0}, v[7] = {0}, g[4];
    int n = order + 1, k, i;
    if (mode == ABU_STICK && tm == 0.0) { /* alpha = T / J_total: the input's derivatives */
        double J = abu_J_total(p);
        out[0] = applied / J;
        for (k = 1; k <= order; k++) out[k] = (k < nd ? td[k] : 0.0) / J;
        return;
    }
    fact[0] = 1.0;
    for (i = 1; i <= n; i++) fact[i] = fact[i - 1] * i;
    for (k = 0; k < n; k++) T[k] = (k < nd ? td[k] : 0.0) / fact[k];
    Ta[0] = applied;
    for (k = 1; k < n; k++) Ta[k] = T[k];
    if (tm != 0.0) /* tm Ta' + Ta = T */
        for (k = 0; k < n - 1; k++) Ta[k + 1] = (T[k] - Ta[k]) / (tm * (k + 1));
    if (mode == ABU_STICK) {
        double J = abu_J_total(p);
        for (k = 0; k < n; k++) out[k] = Ta[k] / J * fact[k];
        return;
    }
    double m = p->m, l = p->l, d = p->d;
    double f_scale = abu_mu_dynamic(p) * mode * m;
    slip_gains(p, g);
    w[0] = omega;
    v[0] = beta_dot;
    for (k = 0; k < n; k++) { /* Cauchy products of the quadratic right-hand side */
        double f_k = 0.0;
        for (i = 0; i <= k; i++) {
            double s_i = w[i] + v[i], s_j = w[k - i] + v[k - i];
            f_k += l * s_i * s_j + 0.4 * l * v[i] * v[k - i] - 0.2 * d * w[i] * v[k - i];
        }
        f_k *= f_scale;
        double a_k = g[0] * Ta[k] + g[1] * f_k;
        out[k] = a_k * fact[k];
        w[k + 1] = a_k / (k + 1);
        v[k + 1] = (g[2] * Ta[k] + g[3] * f_k) / (k + 1);
    }
}

/* ------------------------------------------------------------------ stick trajectories */
/* The stick trajectory from tau0 as functions of u = tau - tau0: polynomials without a
 * motor lag, the closed form of _lag_trajectory with one. */
typedef struct {
    int lag, nT, nP, nIP, nI2P, nA, nDA, nW;
    double T[ABU_MAXC], P[ABU_MAXC], int_P[ABU_MAXC], int2_P[ABU_MAXC];
    double alpha[ABU_MAXC], d_alpha[ABU_MAXC], omega[ABU_MAXC];
    double D, tm, J, omega0, theta0;
    const AbuParams *p;
} Traj;

static double tr_commanded(const Traj *t, double u) { return abu_poly_eval(t->T, t->nT, u); }
static double tr_applied(const Traj *t, double u) {
    return abu_poly_eval(t->P, t->nP, u) + t->D * exp(-u / t->tm);
}
static double tr_omega(const Traj *t, double u) {
    if (!t->lag) return abu_poly_eval(t->omega, t->nW, u);
    return t->omega0 + (abu_poly_eval(t->int_P, t->nIP, u) + t->D * t->tm * -expm1(-u / t->tm))
        / t->J;
}
static double tr_theta(const Traj *t, double u) {
    return t->theta0 + t->omega0 * u + (abu_poly_eval(t->int2_P, t->nI2P, u)
                                        + t->D * t->tm * (u + t->tm * expm1(-u / t->tm))) / t->J;
}
static double tr_alpha(const Traj *t, double u) {
    return t->lag ? tr_applied(t, u) / t->J : abu_poly_eval(t->alpha, t->nA, u);
}
static double tr_alpha_rate(const Traj *t, double u) {
    if (!t->lag) return abu_poly_eval(t->d_alpha, t->nDA, u);
    return (tr_commanded(t, u) - tr_applied(t, u)) / (t->tm * t->J);
}
static double tr_mu_req(const Traj *t, double u) {
    return mu_required(t->p, tr_alpha(t, u), tr_omega(t, u));
}
/* d(mu_req)/du has the sign of alpha (alpha' omega - 2 alpha^2) omega */
static double tr_slope(void *ctx, double u) {
    const Traj *t = ctx;
    double a = tr_alpha(t, u), w = tr_omega(t, u);
    return a * (tr_alpha_rate(t, u) * w - 2.0 * a * a) * w;
}
static double tr_alpha_fn(void *ctx, double u) { return tr_alpha(ctx, u); }

/* Sign of the slope next to `end`, halving from `other` towards it (60 times at most). */
static int near(Traj *t, double end, double other, double sign, double *x_out, double *d_out) {
    double x = other;
    for (int i = 0; i < 60; i++) {
        x = end + 0.5 * (x - end);
        double d = tr_slope(t, x);
        if (sign * d > 0.0) { *x_out = x; *d_out = d; return 1; }
    }
    return 0;
}

/* _fall_through_zero: the u in (lo, hi) where the slope falls through 0 (a maximum). */
static int fall_through_zero(Traj *t, double lo, double hi, int lo_is_zero, int hi_is_zero,
                             double *u) {
    double rx, rd, lx, ld;
    if (hi_is_zero) {
        if (!near(t, hi, lo, -1.0, &rx, &rd)) return 0;
    } else {
        rd = tr_slope(t, hi);
        rx = hi;
        if (!(rd < 0.0)) return 0;
    }
    double d_lo = lo_is_zero ? 0.0 : tr_slope(t, lo);
    if (d_lo > 0.0) { lx = lo; ld = d_lo; }
    else if (d_lo == 0.0) { if (!near(t, lo, rx, 1.0, &lx, &ld)) return 0; }
    else return 0;
    *u = abu_brent_root(tr_slope, t, lx, rx, ld, rd);
    return 1;
}

/* _peak: raise step_peak to the largest mu_req on [0, u_end] in stick. */
static void peak(AbuPlant *pl, Traj *t, double u_end) {
    double p = py_max(py_max(pl->step_peak, tr_mu_req(t, 0.0)), tr_mu_req(t, u_end));
    if (u_end > 0.0) {
        double ends[3] = {0.0, u_end, 0.0};
        int n = 2;
        double a0 = tr_alpha(t, 0.0), a1 = tr_alpha(t, u_end);
        if ((a0 < 0.0) != (a1 < 0.0) && a0 != 0.0 && a1 != 0.0) {
            /* |alpha| passes through 0 (a minimum of mu_req): a maximum on either side */
            ends[2] = u_end;
            ends[1] = abu_brent_root(tr_alpha_fn, t, 0.0, u_end, a0, a1);
            n = 3;
        }
        for (int i = 0; i + 1 < n; i++) {
            double u;
            if (fall_through_zero(t, ends[i], ends[i + 1], i > 0, i + 2 < n, &u))
                p = py_max(p, tr_mu_req(t, u));
        }
    }
    pl->step_peak = p;
}

static double advance_stick_polynomial(AbuPlant *pl, double tau0, double h, const double *c,
                                       int nc, int *failed) {
    const AbuParams *p = &pl->p;
    AbuPlantState *s = &pl->s;
    Traj t;
    memset(&t, 0, sizeof t);
    t.p = p;
    double J = abu_J_total(p), sq[ABU_MAXC], g[ABU_MAXC], th[ABU_MAXC];
    abu_poly_shift(c, nc, tau0, t.T);
    t.nT = nc;
    for (int i = 0; i < nc; i++) t.alpha[i] = t.T[i] / J;
    t.nA = nc;
    t.nW = abu_poly_int(t.alpha, t.nA, s->omega, t.omega);
    int nsq = abu_poly_mul(t.omega, t.nW, t.omega, t.nW, sq);
    for (int i = 0; i < nsq; i++) sq[i] = p->mu * sq[i];
    double k = lever_ratio(p), span = h - tau0, u_fail = 0.0;
    *failed = 0;
    for (int side = 0; side < 2; side++) { /* g = mu omega^2 -/+ k alpha */
        double sign = side == 0 ? 1.0 : -1.0, u;
        memcpy(g, sq, (size_t)nsq * sizeof *g);
        for (int i = 0; i < t.nA; i++) g[i] -= sign * k * t.alpha[i];
        if (abu_poly_first_negative(g, nsq, span, ABU_END_TOLERANCE, &u)
            && (!*failed || u < u_fail)) {
            u_fail = u;
            *failed = 1;
        }
    }
    double u = *failed ? u_fail : span;
    t.nDA = abu_poly_der(t.alpha, t.nA, t.d_alpha);
    if (t.nDA == 0) { t.d_alpha[0] = 0.0; t.nDA = 1; }
    peak(pl, &t, u);
    int nth = abu_poly_int(t.omega, t.nW, s->theta, th);
    s->theta = abu_poly_eval(th, nth, u);
    s->omega = abu_poly_eval(t.omega, t.nW, u);
    s->torque_applied = abu_poly_eval(t.T, t.nT, u);
    return tau0 + u_fail;
}

static void lag_trajectory(const AbuPlant *pl, double tau0, const double *c, int nc, Traj *t) {
    double term[ABU_MAXC], next[ABU_MAXC], factor = 1.0;
    memset(t, 0, sizeof *t);
    t->p = &pl->p;
    t->lag = 1;
    t->tm = pl->p.tau_motor;
    t->J = abu_J_total(&pl->p);
    abu_poly_shift(c, nc, tau0, t->T);
    t->nT = nc;
    memcpy(t->P, t->T, sizeof t->T);
    t->nP = nc;
    memcpy(term, t->T, sizeof term);
    int nterm = nc;
    for (int r = 0; r < nc - 1; r++) { /* P = sum_j (-tm)^j T^(j) */
        nterm = abu_poly_der(term, nterm, next);
        memcpy(term, next, sizeof term);
        factor *= -t->tm;
        for (int i = 0; i < nterm; i++) t->P[i] += factor * term[i];
    }
    t->D = pl->s.torque_applied - t->P[0];
    t->nIP = abu_poly_int(t->P, t->nP, 0.0, t->int_P);
    t->nI2P = abu_poly_int(t->int_P, t->nIP, 0.0, t->int2_P);
    t->omega0 = pl->s.omega;
    t->theta0 = pl->s.theta;
}

/* mu omega^2 - k |alpha| >= 0 while the ball can stick (with a motor lag) */
static double lag_margin(void *ctx, double u) {
    const Traj *t = ctx;
    return t->p->mu * pow(tr_omega(t, u), 2) - lever_ratio(t->p) * fabs(tr_applied(t, u) / t->J);
}

static double advance_stick_lag(AbuPlant *pl, double tau0, double h, const double *c, int nc,
                                int *failed) {
    Traj t;
    lag_trajectory(pl, tau0, c, nc, &t);
    double span = h - tau0, u_fail = 0.0, previous = 0.0;
    int i;
    *failed = 0;
    for (i = 0; i <= ABU_LAG_BRACKET_POINTS; i++) {
        double u = span * i / ABU_LAG_BRACKET_POINTS, value = lag_margin(&t, u);
        if (value < 0.0) {
            u_fail = i == 0 ? 0.0 : abu_brent_root(lag_margin, &t, previous, u,
                                                    lag_margin(&t, previous), value);
            *failed = 1;
            break;
        }
        previous = u;
    }
    if (!*failed && lag_margin(&t, span + ABU_END_TOLERANCE) < 0.0) { /* a root at the end */
        u_fail = span;
        *failed = 1;
    }
    double u_end = *failed ? u_fail : span;
    peak(pl, &t, u_end);
    pl->s.theta = tr_theta(&t, u_end);
    pl->s.omega = tr_omega(&t, u_end);
    pl->s.torque_applied = tr_applied(&t, u_end);
    return tau0 + u_fail;
}

/* ------------------------------------------------------------------ slip */
typedef struct {
    double f_scale, l, d, tm, g[4], drive[ABU_MAXC];
    int n_drive; /* descending coefficients of T (lag) or T' (no lag) */
} SlipCtx;

static void slip_rhs(void *ctx, double tau, const double *y, double *dy) {
    const SlipCtx *s = ctx;
    double omega = y[1], v = y[3], applied = y[4];
    double f_w = s->f_scale * (s->l * pow(omega + v, 2) + 0.4 * s->l * v * v
                               - 0.2 * s->d * omega * v);
    double value = 0.0;
    for (int i = 0; i < s->n_drive; i++) value = value * tau + s->drive[i];
    dy[0] = omega;
    dy[1] = s->g[0] * applied + s->g[1] * f_w;
    dy[2] = v;
    dy[3] = s->g[2] * applied + s->g[3] * f_w;
    dy[4] = s->tm == 0.0 ? value : (value - applied) / s->tm;
}

static void slip_setup(const AbuParams *p, int direction, const double *c, int nc, SlipCtx *s) {
    double der[ABU_MAXC];
    const double *src = c;
    int n = nc;
    s->f_scale = abu_mu_dynamic(p) * direction * p->m;
    s->l = p->l;
    s->d = p->d;
    s->tm = p->tau_motor;
    slip_gains(p, s->g);
    if (s->tm == 0.0) {
        n = abu_poly_der(c, nc, der);
        src = der;
    }
    if (n == 0) { s->drive[0] = 0.0; s->n_drive = 1; return; }
    for (int i = 0; i < n; i++) s->drive[i] = src[n - 1 - i];
    s->n_drive = n;
}

/* Returns 1 with *tau_zero at beta' = 0, 0 at h, -1 on failure (message). */
static int advance_slip(AbuPlant *pl, double tau0, double h, const double *c, int nc,
                        double *tau_zero, char *msg, int size) {
    AbuPlantState *s = &pl->s;
    int direction = s->mode;
    if (h <= tau0) return 0;
    SlipCtx ctx;
    slip_setup(&pl->p, direction, c, nc, &ctx);
    double y0[ABU_NY] = {s->theta, s->omega, s->beta, s->beta_dot, s->torque_applied};
    double y[ABU_NY], tau, scale = 0.0, atol[ABU_NY];
    for (int i = 0; i < nc; i++) {
        double v = fabs(c[i]) * pow(h, i);
        if (i == 0 || v > scale) scale = v;
    }
    scale = py_max(scale, 1e-12);
    atol[0] = 1e-14; atol[1] = 1e-12; atol[2] = 1e-14; atol[3] = 1e-12; atol[4] = 1e-13 * scale;
    char problem[200] = "";
    int stopped = abu_integrate_until(slip_rhs, &ctx, tau0, y0, h, ABU_SLIP_RTOL, atol, 3,
                                      (double)direction, &tau, y, problem, sizeof problem);
    if (stopped < 0) {
        snprintf(msg, (size_t)size, "slip integration failed at t = %.9g s: %s", s->time + tau0,
                 problem);
        return -1;
    }
    if (!stopped && direction * y[3] > 0.0) { /* a stop within END_TOLERANCE after h */
        double y_late[ABU_NY];
        abu_rk45_step(slip_rhs, &ctx, h, y, ABU_END_TOLERANCE, NULL, y_late, NULL, NULL);
        stopped = direction * y_late[3] <= 0.0;
    }
    s->theta = y[0]; s->omega = y[1]; s->beta = y[2]; s->beta_dot = y[3];
    s->torque_applied = y[4];
    if (stopped) *tau_zero = tau < h ? tau : h;
    if (pl->p.tau_motor == 0.0) s->torque_applied = abu_poly_eval(c, nc, stopped ? *tau_zero : h);
    return stopped;
}

/* ------------------------------------------------------------------ stepping */
static void do_switch(AbuPlant *pl, double t, int new_mode, int *n, double *first) {
    if (*n == 0) *first = t;
    (*n)++;
    pl->s.mode = new_mode;
    pl->s.switch_count++;
    pl->s.t_last_switch = t;
}

int abu_plant_advance(AbuPlant *pl, double h, const double td[5], int *n_switches,
                      double *t_first_switch, char *msg, int size) {
    const AbuParams *p = &pl->p;
    AbuPlantState *s = &pl->s;
    double c[5] = {td[0], td[1], 0.5 * td[2], td[3] / 6.0, td[4] / 24.0};
    int nc = 5;
    if (!(h >= 0.0 && isfinite(h))) {
        snprintf(msg, (size_t)size, "step size must be finite and >= 0 s, got %.17g", h);
        return -1;
    }
    while (nc > 1 && c[nc - 1] == 0.0) nc--; /* a lower-order hold keeps cheaper polynomials */
    if (p->tau_motor == 0.0) s->torque_applied = td[0];
    pl->step_peak = 0.0;
    double start = s->time, tau = 0.0;
    *n_switches = 0;
    for (;;) {
        int failed;
        if (s->mode == ABU_STICK) {
            if (!stick_holds(p, s->torque_applied, s->omega)) {
                do_switch(pl, start + tau, slip_direction(p, s->torque_applied), n_switches,
                          t_first_switch);
                continue;
            }
            double tau_fail = p->tau_motor == 0.0
                ? advance_stick_polynomial(pl, tau, h, c, nc, &failed)
                : advance_stick_lag(pl, tau, h, c, nc, &failed);
            if (!failed) break;
            tau = tau_fail;
            do_switch(pl, start + tau, slip_direction(p, s->torque_applied), n_switches,
                      t_first_switch);
        } else {
            double tau_zero;
            int r = advance_slip(pl, tau, h, c, nc, &tau_zero, msg, size);
            if (r < 0) return -1;
            if (r == 0) break;
            tau = tau_zero;
            s->beta_dot = 0.0;
            int new_mode = stick_holds(p, s->torque_applied, s->omega)
                ? ABU_STICK : slip_direction(p, s->torque_applied);
            do_switch(pl, start + tau, new_mode, n_switches, t_first_switch);
        }
        if (*n_switches > ABU_MAX_SWITCHES_PER_STEP) {
            snprintf(msg, (size_t)size, "more than %d stick/slip switches in the step at "
                     "t = %.9g s (chattering)", ABU_MAX_SWITCHES_PER_STEP, start);
            return -1;
        }
        if (tau >= h) break;
    }
    s->time = start + h;
    return 0;
}
