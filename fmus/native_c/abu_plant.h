/*
 * abu_plant.h - C99 port of abu_model/params.py, dynamics.py and plant.py: the ABU rotor
 * with one ball, stepped with exact stick/slip switches (the AbuBall FMU's model).
 */
#ifndef ABU_PLANT_H
#define ABU_PLANT_H

#define ABU_STICK 0
/* A switch located within this time of a step's end [s] is taken at the step's end. */
#define ABU_END_TOLERANCE 1e-12
/* More switches than this inside one step means chattering. */
#define ABU_MAX_SWITCHES_PER_STEP 50
/* Grid that brackets the stick test's first root with a motor lag. */
#define ABU_LAG_BRACKET_POINTS 64
#define ABU_SLIP_RTOL 1e-12

/* BallParams + PlantParams (SI). mu_d < 0 means mu_d = mu (the FMU's convention). */
typedef struct {
    double m, d, l, mu, mu_d, J_abu, tau_motor;
    int ball_reaction;
} AbuParams;

/* PlantState: everything a rollback must restore. */
typedef struct {
    double time, theta, omega, beta, beta_dot, torque_applied;
    int mode, switch_count;
    double t_last_switch; /* -inf before any switch */
} AbuPlantState;

typedef struct {
    AbuParams p;
    AbuPlantState s;
    double step_peak; /* largest mu_req in stick over the last step (0 without stick) */
} AbuPlant;

typedef struct {
    double alpha, beta_ddot, normal_force, friction_force, mu_req;
} AbuOutputs;

/* 0 if the parameters are valid, else 1 with a message naming the first bad one. */
int abu_params_check(const AbuParams *p, char *msg, int size);
double abu_mu_dynamic(const AbuParams *p);
double abu_J_total(const AbuParams *p);

void abu_plant_outputs(const AbuPlant *pl, double torque, AbuOutputs *out);
/* d^k alpha/dt^k for k = 0..order (order <= 4), commanded torque derivatives td[0..nd-1]. */
void abu_alpha_taylor(const AbuParams *p, const double *td, int nd, double applied,
                      double omega, double beta_dot, int mode, int order, double *out);
double abu_applied_torque(const AbuPlant *pl, double torque);

/* Advance by h with T(tau) = sum td[k] tau^k / k! (td: torque .. snap). Returns 0 with the
 * number of switches and the first switch time, or -1 with a message (state undefined:
 * the caller restores its copy). */
int abu_plant_advance(AbuPlant *pl, double h, const double td[5], int *n_switches,
                      double *t_first_switch, char *msg, int size);

#endif
