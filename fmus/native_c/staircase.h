/*
 * staircase.h - C99 port of controller/reference.py: the staircase approximation of the
 * inclined sine with exact step times (roots of p(s) = s - sin(2 pi s)/(2 pi)), computed on
 * demand so that the FMU's state stays a plain struct (no table of step times).
 */
#ifndef ABU_STAIRCASE_H
#define ABU_STAIRCASE_H

#define ABU_STAIRCASE_MAX_STEPS 100000

typedef struct {
    double omega0, omega_end, t0, te, step;
    int rounding; /* 0 lead, 1 nearest, 2 trail */
} AbuStaircase;

/* 0 with the number of steps in *n if valid, else 1 with a message. */
int abu_staircase_check(const AbuStaircase *s, int *n, char *msg, int size);
/* Time of step k = 1..n [s]. */
double abu_staircase_time(const AbuStaircase *s, int n, int k);
/* Setpoint after k steps [rad/s]. */
double abu_staircase_level(const AbuStaircase *s, int k);
/* Number of steps at time t (bisect_right over the step times). */
int abu_staircase_index(const AbuStaircase *s, int n, double t);
/* The same, walking from a known index `hint` (cheap when t moved by about a step). */
int abu_staircase_index_from(const AbuStaircase *s, int n, double t, int hint);

#endif
