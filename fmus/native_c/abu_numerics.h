/*
 * abu_numerics.h - C99 port of abu_model/numerics.py (polynomials, bracketing root finder,
 * Dormand-Prince 5(4) with event location), operation for operation, so that the native
 * FMUs reproduce the Python plant to the last bits (same IEEE operations in the same order).
 * Build with -ffp-contract=off: a fused multiply-add would round differently.
 */
#ifndef ABU_NUMERICS_H
#define ABU_NUMERICS_H

/* Most coefficients of a polynomial here: the stick test omega^2 of a degree-4 torque hold
 * has degree 10 (11 coefficients); one more for integrals. */
#define ABU_MAXC 16

/* A scalar function with its context (root finding on closures of the Python code). */
typedef double (*abu_fn)(void *ctx, double x);

double abu_ulp(double x);
double abu_poly_eval(const double *c, int n, double x);
int abu_poly_der(const double *c, int n, double *out);
void abu_poly_shift(const double *c, int n, double x0, double *out);
int abu_poly_mul(const double *a, int na, const double *b, int nb, double *out);
int abu_poly_int(const double *c, int n, double c0, double *out);
double abu_brent_root(abu_fn f, void *ctx, double a, double b, double fa, double fb);
int abu_poly_first_negative(const double *c, int n, double span, double end_tolerance,
                            double *u);

/* The slip ODE has 5 components; f(ctx, t, y, dy). */
#define ABU_NY 5
typedef void (*abu_rhs)(void *ctx, double t, const double *y, double *dy);

void abu_rk45_step(abu_rhs f, void *ctx, double t, const double *y, double h,
                   const double *k0, double *y_new, double *err, double *k7);

/* integrate_until with the event g = sign * y[index] (a fall from > 0 to <= 0 stops) and
 * its slope sign * y'[index]. Returns 0 (reached t_end), 1 (stopped at the event), or
 * -1 (arithmetic failure, message in `problem`). */
int abu_integrate_until(abu_rhs f, void *ctx, double t0, const double *y0, double t_end,
                        double rtol, const double *atol, int event_index, double event_sign,
                        double *t_out, double *y_out, char *problem, int problem_size);

#endif
