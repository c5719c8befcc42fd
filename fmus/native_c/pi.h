/*
 * pi.h - C99 port of controller/pi.py: the identified PI speed law with the torque's
 * derivatives for a Taylor hold (the SpeedController FMU's model).
 */
#ifndef ABU_PI_H
#define ABU_PI_H

#define ABU_THETA_REF_INTEGRAL 0
#define ABU_THETA_REF_THESIS 1

typedef struct {
    double zeta, omega_n, J_abu;
    int theta_ref_mode; /* 0 integral, 1 thesis */
} AbuPI;

/* 0 if valid, else 1 with a message naming the bad parameter. */
int abu_pi_check(const AbuPI *pi, char *msg, int size);
double abu_pi_kp(const AbuPI *pi);
double abu_pi_ki(const AbuPI *pi);
double abu_pi_torque(const AbuPI *pi, double t, double omega_ref, double omega, double theta,
                     double x_i);
double abu_pi_torque_rate(const AbuPI *pi, double omega_ref, double omega, double alpha);
double abu_pi_torque_derivative(const AbuPI *pi, double d_k, double d_k_minus_1);
/* x_I(t+h) - x_I(t) with omega(tau) the Taylor polynomial of alpha, jerk, snap, crackle. */
double abu_pi_integral_increment(double h, double omega_ref, double omega, double alpha,
                                 double jerk, double snap, double crackle);

#endif
