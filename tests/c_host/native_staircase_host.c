/*
 * A portable FMI 2.0 host (Linux and Windows, no Python, no libcosim) for the native FMUs:
 * the report's staircase in closed loop, Staircase -> SpeedController <-> AbuBall, with the
 * fourth-order Taylor hold of the master's connections, at a fixed step.
 *
 *   native_staircase_host ABUBALL_BIN ABUBALL_GUID CTRL_BIN CTRL_GUID REF_BIN REF_GUID STEPS
 *
 * Start values of the three FMUs (the report's -17 Hz -> -22 Hz in 1 s, mu = 2.75e-3) from
 * t = -0.05 s, STEPS steps of 1 ms, outputs set in connection order before every step (a
 * Gauss-Seidel-free fixed-step master: all outputs are read, then all inputs set, then every
 * FMU steps). Prints, like tests/c_host/abu_cosim_host.c,
 *
 *   t_slip=<s> mu_low=<1> mu_high=<1> steps=<n>
 *
 * t_slip: the plant's t_last_switch after the first step that ends in slip; mu_low: the
 * largest mu_req of the points in stick before it; mu_high: mu_req at that point (read
 * before the point's new inputs are set: left-hand limits).
 * tests/test_native_win64.py runs it as a Linux and as a win64 (wine) program.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#ifdef _WIN32
#include <windows.h>
static void *load(const char *path) { return (void *)LoadLibraryA(path); }
static void *sym(void *lib, const char *name) {
    return (void *)(size_t)GetProcAddress((HMODULE)lib, name);
}
#else
#include <dlfcn.h>
static void *load(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *sym(void *lib, const char *name) { return dlsym(lib, name); }
#endif

typedef struct {
    fmi2Component c;
    fmi2InstantiateTYPE *instantiate;
    fmi2SetupExperimentTYPE *setup;
    fmi2EnterInitializationModeTYPE *enter;
    fmi2ExitInitializationModeTYPE *exit_init;
    fmi2SetRealTYPE *set_real;
    fmi2GetRealTYPE *get_real;
    fmi2GetIntegerTYPE *get_integer;
    fmi2DoStepTYPE *do_step;
    fmi2FreeInstanceTYPE *free_instance;
} Fmu;

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    (void)env; (void)category;
    fprintf(stderr, "%s [%d]: %s\n", name, (int)status, message);
}

static int open_fmu(Fmu *f, const char *path, const char *guid, const char *name,
                    const fmi2CallbackFunctions *cb) {
    void *lib = load(path);
    if (lib == NULL) return fprintf(stderr, "cannot load %s\n", path), 0;
    f->instantiate = (fmi2InstantiateTYPE *)sym(lib, "fmi2Instantiate");
    f->setup = (fmi2SetupExperimentTYPE *)sym(lib, "fmi2SetupExperiment");
    f->enter = (fmi2EnterInitializationModeTYPE *)sym(lib, "fmi2EnterInitializationMode");
    f->exit_init = (fmi2ExitInitializationModeTYPE *)sym(lib, "fmi2ExitInitializationMode");
    f->set_real = (fmi2SetRealTYPE *)sym(lib, "fmi2SetReal");
    f->get_real = (fmi2GetRealTYPE *)sym(lib, "fmi2GetReal");
    f->get_integer = (fmi2GetIntegerTYPE *)sym(lib, "fmi2GetInteger");
    f->do_step = (fmi2DoStepTYPE *)sym(lib, "fmi2DoStep");
    f->free_instance = (fmi2FreeInstanceTYPE *)sym(lib, "fmi2FreeInstance");
    if (!f->instantiate || !f->setup || !f->enter || !f->exit_init || !f->set_real
        || !f->get_real || !f->get_integer || !f->do_step || !f->free_instance)
        return fprintf(stderr, "%s lacks an FMI function\n", path), 0;
    f->c = f->instantiate(name, fmi2CoSimulation, guid, "", cb, fmi2False, fmi2False);
    return f->c != NULL;
}

/* A connection: source FMU and value reference -> destination FMU and value reference. */
typedef struct { int src; fmi2ValueReference svr; int dst; fmi2ValueReference dvr; } Link;
enum { PLANT, CTRL, REF };

/* The value references of the modelDescription.xml (the Python FMUs' too). */
static const Link LINKS[] = {
    {REF, 6, CTRL, 5},      /* omega_ref */
    {PLANT, 15, CTRL, 6},   /* omega */
    {PLANT, 14, CTRL, 7},   /* theta */
    {PLANT, 16, CTRL, 8},   /* alpha */
    {CTRL, 10, PLANT, 12},  /* torque */
    {CTRL, 11, PLANT, 13},  /* torque_rate */
    {PLANT, 24, CTRL, 9},   /* jerk */
    {PLANT, 33, CTRL, 14},  /* snap */
    {PLANT, 34, CTRL, 15},  /* crackle */
    {CTRL, 12, PLANT, 30},  /* torque_accel */
    {CTRL, 16, PLANT, 31},  /* torque_jerk */
    {CTRL, 17, PLANT, 32},  /* torque_snap */
};
#define N_LINKS (sizeof LINKS / sizeof LINKS[0])

/* Every output read first, then every input set: one coupled point. */
static int exchange(Fmu *fmu) {
    double v[N_LINKS];
    for (size_t i = 0; i < N_LINKS; i++)
        if (fmu[LINKS[i].src].get_real(fmu[LINKS[i].src].c, &LINKS[i].svr, 1, &v[i])) return 0;
    for (size_t i = 0; i < N_LINKS; i++)
        if (fmu[LINKS[i].dst].set_real(fmu[LINKS[i].dst].c, &LINKS[i].dvr, 1, &v[i])) return 0;
    return 1;
}

int main(int argc, char **argv) {
    Fmu fmu[3];
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    const char *names[3] = {"plant", "ctrl", "ref"};
    const double h = 1e-3, t_start = -0.05;
    const fmi2ValueReference theta0 = 8, omega0 = 9, probe[2] = {22, 27}, mode_vr = 25;
    if (argc != 8) return fprintf(stderr, "usage: see the header of this file\n"), 2;
    int steps = atoi(argv[7]);
    for (int i = 0; i < 3; i++)
        if (!open_fmu(&fmu[i], argv[1 + 2 * i], argv[2 + 2 * i], names[i], &cb)) return 1;
    double w0;
    fmu[PLANT].get_real(fmu[PLANT].c, &omega0, 1, &w0);
    double th0 = w0 * t_start; /* steady rotation before the start, as the experiments */
    fmu[PLANT].set_real(fmu[PLANT].c, &theta0, 1, &th0);
    for (int i = 0; i < 3; i++)
        if (fmu[i].setup(fmu[i].c, fmi2False, 0.0, t_start, fmi2False, 0.0)
            || fmu[i].enter(fmu[i].c)) return 1;
    for (int i = 0; i < 3; i++)
        if (fmu[i].exit_init(fmu[i].c)) return 1;
    double mu_low = 0.0, mu_high = NAN, t_slip = NAN;
    for (int k = 0; k <= steps; k++) {
        double t = t_start + k * h, values[2];
        fmi2Integer mode;
        fmu[PLANT].get_real(fmu[PLANT].c, probe, 2, values); /* before the new inputs */
        fmu[PLANT].get_integer(fmu[PLANT].c, &mode_vr, 1, &mode);
        if (!exchange(fmu)) return 1;
        if (mode == 0 && isnan(mu_high) && values[0] > mu_low) mu_low = values[0];
        if (mode != 0 && isnan(mu_high)) { mu_high = values[0]; t_slip = values[1]; }
        if (k < steps)
            for (int i = 0; i < 3; i++)
                if (fmu[i].do_step(fmu[i].c, t, h, fmi2True)) return 1;
    }
    for (int i = 0; i < 3; i++) fmu[i].free_instance(fmu[i].c);
    printf("t_slip=%.17g mu_low=%.17g mu_high=%.17g steps=%d\n", t_slip, mu_low, mu_high, steps);
    return 0;
}
