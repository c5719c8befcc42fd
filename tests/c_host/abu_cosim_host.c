/*
 * A non-Python FMI host: runs an SSP archive written by `abu export-ssp` through libcosim's
 * C API (libcosimc, the library the libcosimpy wheel ships) and prints where the ball first
 * slips.
 *
 *   abu_cosim_host ABU.ssp STEPS
 *
 * STEPS communication steps of the SSD's fixed step are taken (libcosim's C API does not
 * expose the default experiment's stop time). The process has no Python of its own: the FMUs must load and embed the interpreter
 * themselves (no LD_PRELOAD). Output, one line on success (times in s):
 *
 *   t_slip=<s> mu_low=<1> mu_high=<1> steps=<n> end=<s>
 *
 * t_slip is the plant's t_last_switch at the first step that ends in slip (mode != 0),
 * mu_low the largest mu_req of the stuck steps before it, mu_high mu_req at that step; "none"
 * if the ball never slips. Exit status 0 on success, 1 on any error (message on stderr).
 *
 * The libcosimpy wheel ships libcosimc.so but no header, so the few declarations needed are
 * written out here; they follow include/cosim.h of open-simulation-platform/libcosimc.
 */
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- the subset of libcosimc's cosim.h used here ---- */
typedef int64_t cosim_time_point; /* ns */
typedef int64_t cosim_duration;   /* ns */
typedef uint32_t cosim_value_reference;
typedef int cosim_slave_index;
typedef struct cosim_execution_s cosim_execution;
typedef struct cosim_observer_s cosim_observer;
#define SLAVE_NAME_MAX_SIZE 1024

typedef enum { COSIM_EXECUTION_STOPPED, COSIM_EXECUTION_RUNNING, COSIM_EXECUTION_ERROR }
    cosim_execution_state;
typedef struct {
    cosim_time_point current_time;
    cosim_execution_state state;
    int error_code;
    double total_average_real_time_factor;
    double rolling_average_real_time_factor;
    double real_time_factor_target;
    int is_real_time_simulation;
    int steps_to_monitor;
} cosim_execution_status;
typedef enum {
    COSIM_VARIABLE_TYPE_REAL, COSIM_VARIABLE_TYPE_INTEGER, COSIM_VARIABLE_TYPE_STRING,
    COSIM_VARIABLE_TYPE_BOOLEAN
} cosim_variable_type;
typedef struct {
    char name[SLAVE_NAME_MAX_SIZE];
    cosim_value_reference reference;
    cosim_variable_type type;
    int causality;
    int variability;
} cosim_variable_description;
typedef struct {
    char name[SLAVE_NAME_MAX_SIZE];
    cosim_slave_index index;
} cosim_slave_info;
typedef enum {
    COSIM_LOG_SEVERITY_TRACE, COSIM_LOG_SEVERITY_DEBUG, COSIM_LOG_SEVERITY_INFO,
    COSIM_LOG_SEVERITY_WARNING, COSIM_LOG_SEVERITY_ERROR, COSIM_LOG_SEVERITY_FATAL
} cosim_log_severity_level;

const char* cosim_last_error_message(void);
int cosim_log_setup_simple_console_logging(void);
void cosim_log_set_output_level(cosim_log_severity_level level);
cosim_execution* cosim_ssp_execution_create(const char* sspDir, bool startTimeDefined,
                                            cosim_time_point startTime);
int cosim_execution_destroy(cosim_execution* execution);
int cosim_execution_step(cosim_execution* execution, size_t numSteps);
int cosim_execution_get_status(cosim_execution* execution, cosim_execution_status* status);
size_t cosim_execution_get_num_slaves(cosim_execution* execution);
int cosim_execution_get_slave_infos(cosim_execution* execution, cosim_slave_info infos[],
                                    size_t numSlaves);
int cosim_slave_get_num_variables(cosim_execution* execution, cosim_slave_index slave);
int cosim_slave_get_variables(cosim_execution* execution, cosim_slave_index slave,
                              cosim_variable_description variables[], size_t numVariables);
cosim_observer* cosim_last_value_observer_create(void);
int cosim_observer_destroy(cosim_observer* observer);
int cosim_execution_add_observer(cosim_execution* execution, cosim_observer* observer);
int cosim_observer_slave_get_real(cosim_observer* observer, cosim_slave_index slave,
                                  const cosim_value_reference variables[], size_t nv,
                                  double values[]);
int cosim_observer_slave_get_integer(cosim_observer* observer, cosim_slave_index slave,
                                     const cosim_value_reference variables[], size_t nv,
                                     int values[]);

/* ---- the host ---- */
static int fail(const char* what)
{
    fprintf(stderr, "abu_cosim_host: %s failed: %s\n", what, cosim_last_error_message());
    return 1;
}

/* Value reference of `name` (of `type`) in slave `slave`; -1 if missing. */
static int64_t find_variable(cosim_execution* ex, cosim_slave_index slave, const char* name,
                             cosim_variable_type type)
{
    int n = cosim_slave_get_num_variables(ex, slave);
    if (n <= 0) return -1;
    cosim_variable_description* vars = calloc((size_t)n, sizeof *vars);
    if (!vars) return -1;
    int got = cosim_slave_get_variables(ex, slave, vars, (size_t)n);
    int64_t ref = -1;
    for (int i = 0; i < got; ++i) {
        if (strcmp(vars[i].name, name) == 0 && vars[i].type == type) {
            ref = vars[i].reference;
            break;
        }
    }
    free(vars);
    return ref;
}

static int run(const char* ssp, long steps)
{
    cosim_execution* ex = cosim_ssp_execution_create(ssp, false, 0);
    if (!ex) return fail("cosim_ssp_execution_create");

    int status = 1;
    cosim_observer* obs = NULL;
    size_t n_slaves = cosim_execution_get_num_slaves(ex);
    cosim_slave_info infos[8];
    if (n_slaves == 0 || n_slaves > 8 || cosim_execution_get_slave_infos(ex, infos, n_slaves) != 0) {
        fail("cosim_execution_get_slave_infos");
        goto done;
    }
    cosim_slave_index plant = -1;
    for (size_t i = 0; i < n_slaves; ++i)
        if (strcmp(infos[i].name, "plant") == 0) plant = infos[i].index;
    if (plant < 0) {
        fprintf(stderr, "abu_cosim_host: no component 'plant' in %s\n", ssp);
        goto done;
    }
    int64_t vr_mode = find_variable(ex, plant, "mode", COSIM_VARIABLE_TYPE_INTEGER);
    int64_t vr_tsw = find_variable(ex, plant, "t_last_switch", COSIM_VARIABLE_TYPE_REAL);
    int64_t vr_mu = find_variable(ex, plant, "mu_req", COSIM_VARIABLE_TYPE_REAL);
    if (vr_mode < 0 || vr_tsw < 0 || vr_mu < 0) {
        fprintf(stderr, "abu_cosim_host: plant lacks mode, t_last_switch or mu_req\n");
        goto done;
    }
    obs = cosim_last_value_observer_create();
    if (!obs || cosim_execution_add_observer(ex, obs) != 0) {
        fail("cosim_execution_add_observer");
        goto done;
    }
    const cosim_value_reference reals[2] = {(cosim_value_reference)vr_tsw,
                                            (cosim_value_reference)vr_mu};
    const cosim_value_reference ints[1] = {(cosim_value_reference)vr_mode};
    double mu_low = 0.0, mu_high = NAN, t_slip = NAN;
    long k = 0;
    for (; k < steps; ++k) {
        if (cosim_execution_step(ex, 1) != 0) {
            fail("cosim_execution_step");
            goto done;
        }
        double values[2];
        int mode[1];
        if (cosim_observer_slave_get_real(obs, plant, reals, 2, values) != 0 ||
            cosim_observer_slave_get_integer(obs, plant, ints, 1, mode) != 0) {
            fail("cosim_observer_slave_get_*");
            goto done;
        }
        if (!isnan(t_slip)) continue; /* slipped already: run on to the end */
        if (mode[0] != 0) {
            t_slip = values[0];
            mu_high = values[1];
        } else if (values[1] > mu_low) {
            mu_low = values[1];
        }
    }
    cosim_execution_status st;
    if (cosim_execution_get_status(ex, &st) != 0) {
        fail("cosim_execution_get_status");
        goto done;
    }
    if (isnan(t_slip))
        printf("t_slip=none mu_low=%.17g mu_high=none steps=%ld end=%.9f\n", mu_low, k,
               st.current_time * 1e-9);
    else
        printf("t_slip=%.17g mu_low=%.17g mu_high=%.17g steps=%ld end=%.9f\n", t_slip, mu_low,
               mu_high, k, st.current_time * 1e-9);
    status = 0;
done:
    if (cosim_execution_destroy(ex) != 0 && status == 0) status = fail("cosim_execution_destroy");
    if (obs) cosim_observer_destroy(obs);
    return status;
}

int main(int argc, char** argv)
{
    if (argc != 3) {
        fprintf(stderr, "usage: abu_cosim_host ABU.ssp STEPS\n");
        return 2;
    }
    long steps = strtol(argv[2], NULL, 10);
    if (steps <= 0) {
        fprintf(stderr, "abu_cosim_host: STEPS must be a positive integer\n");
        return 2;
    }
    cosim_log_setup_simple_console_logging();
    cosim_log_set_output_level(COSIM_LOG_SEVERITY_WARNING);
    return run(argv[1], steps);
}
