/*
 * pi.c - see pi.h; mirrors controller/pi.py expression by expression (the native and the
 * Python SpeedController must agree to the last bits).
 */
#include "pi.h"

#include <math.h>
#include <stdio.h>

static int positive(double value, const char *name, const char *unit, char *msg, int size) {
    if (isfinite(value) && value > 0.0) return 0;
    snprintf(msg, (size_t)size, "invalid parameter '%s' = %.17g: expected a finite number > 0%s%s",
             name, value, unit[0] ? " " : "", unit);
    return 1;
}

int abu_pi_check(const AbuPI *pi, char *msg, int size) {
    if (positive(pi->zeta, "zeta", "", msg, size)) return 1;
    if (positive(pi->omega_n, "omega_n", "rad/s", msg, size)) return 1;
    if (positive(pi->J_abu, "J_abu", "kg m^2", msg, size)) return 1;
    if (pi->theta_ref_mode != ABU_THETA_REF_INTEGRAL && pi->theta_ref_mode != ABU_THETA_REF_THESIS) {
        snprintf(msg, (size_t)size, "invalid parameter 'theta_ref_mode' = %d: expected 0 "
                 "(integral) or 1 (thesis)", pi->theta_ref_mode);
        return 1;
    }
    return 0;
}

double abu_pi_kp(const AbuPI *pi) { return 2.0 * pi->zeta * pi->omega_n * pi->J_abu; }
double abu_pi_ki(const AbuPI *pi) { return pow(pi->omega_n, 2) * pi->J_abu; }

double abu_pi_torque(const AbuPI *pi, double t, double omega_ref, double omega, double theta,
                     double x_i) {
    double e = pi->theta_ref_mode == ABU_THETA_REF_INTEGRAL ? x_i : t * omega_ref - theta;
    return abu_pi_kp(pi) * (omega_ref - omega) + abu_pi_ki(pi) * e;
}

double abu_pi_torque_rate(const AbuPI *pi, double omega_ref, double omega, double alpha) {
    return -abu_pi_kp(pi) * alpha + abu_pi_ki(pi) * (omega_ref - omega);
}

double abu_pi_torque_derivative(const AbuPI *pi, double d_k, double d_k_minus_1) {
    return -abu_pi_kp(pi) * d_k - abu_pi_ki(pi) * d_k_minus_1;
}

double abu_pi_integral_increment(double h, double omega_ref, double omega, double alpha,
                                 double jerk, double snap, double crackle) {
    double higher[3] = {jerk, snap, crackle};
    double value = (omega_ref - omega) * h - 0.5 * alpha * h * h;
    double power = h * h, factorial = 2.0;
    for (int k = 3; k <= 5; k++) {
        power *= h;
        factorial *= k;
        value -= higher[k - 3] * power / factorial;
    }
    return value;
}
