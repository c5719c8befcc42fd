/* A minimal non-Python FMI 2.0 host for tests/test_fmu_native.py.
 *
 * usage: fmu_c_host <binary.so> <resources dir> <guid> <steps> <vr to print> [bad]
 * dlopens the FMU's binary (no libpython in this process), instantiates, initialises, takes
 * <steps> steps of 1 ms, prints "value <x>" of the Real <vr>, frees, dlcloses, exits 0.
 * With "bad", also makes mistakes a host may make (NaN time, wrong time, garbage state,
 * calls after a refused call) and prints each status.
 */
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef void *C;
typedef struct {
    void (*logger)(void *, const char *, int, const char *, const char *, ...);
    void *(*alloc)(size_t, size_t);
    void (*free)(void *);
    void *step_finished;
    void *env;
} Callbacks;

static void logger(void *env, const char *name, int status, const char *cat, const char *msg, ...) {
    (void)env; (void)cat;
    printf("log %s %d %s\n", name, status, msg);
}

typedef C (*Instantiate)(const char *, int, const char *, const char *, const Callbacks *, int, int);
typedef void (*Free)(C);
typedef int (*Setup)(C, int, double, double, int, double);
typedef int (*Simple)(C);
typedef int (*Step)(C, double, double, int);
typedef int (*GetReal)(C, const unsigned *, size_t, double *);
typedef int (*Deserialize)(C, const char *, size_t, void **);
typedef int (*SetState)(C, void *);
#define LOAD(name, type) type name = (type)dlsym(lib, #name); if (!name) { printf("missing %s\n", #name); return 3; }

int main(int argc, char **argv) {
    if (argc < 6) return 2;
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { printf("dlopen: %s\n", dlerror()); return 4; }
    LOAD(fmi2Instantiate, Instantiate)
    LOAD(fmi2FreeInstance, Free)
    LOAD(fmi2SetupExperiment, Setup)
    LOAD(fmi2EnterInitializationMode, Simple)
    LOAD(fmi2ExitInitializationMode, Simple)
    LOAD(fmi2DoStep, Step)
    LOAD(fmi2GetReal, GetReal)
    LOAD(fmi2DeSerializeFMUstate, Deserialize)
    LOAD(fmi2SetFMUstate, SetState)
    LOAD(fmi2Terminate, Simple)
    char uri[4200];
    snprintf(uri, sizeof uri, "file://%s", argv[2]);
    Callbacks cb = {logger, calloc, free, NULL, NULL};
    C c = fmi2Instantiate("host", 1, argv[3], uri, &cb, 0, 0);
    if (!c) { printf("instantiate failed\n"); return 5; }
    int steps = atoi(argv[4]);
    unsigned vr = (unsigned)atoi(argv[5]);
    int bad = argc > 6 && strcmp(argv[6], "bad") == 0;
    if (bad) printf("status early-step %d\n", fmi2DoStep(c, 0.0, 1e-3, 1));
    if (fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0) || fmi2EnterInitializationMode(c) ||
        fmi2ExitInitializationMode(c)) { printf("init failed\n"); return 6; }
    double t = 0.0, value = NAN;
    for (int i = 0; i < steps; i++, t += 1e-3)
        if (fmi2DoStep(c, t, 1e-3, 1)) { printf("step failed at %g\n", t); return 7; }
    if (fmi2GetReal(c, &vr, 1, &value)) { printf("getReal failed\n"); return 8; }
    printf("value %.17g\n", value);
    if (bad) {
        void *state = NULL;
        printf("status nan-step %d\n", fmi2DoStep(c, NAN, 1e-3, 1));
        printf("status wrong-time %d\n", fmi2DoStep(c, t + 5.0, 1e-3, 1));
        printf("status garbage-state %d\n", fmi2DeSerializeFMUstate(c, "garbage", 7, &state));
        printf("status set-garbage-pointer %d\n", fmi2SetFMUstate(c, (void *)&vr));
        unsigned unknown = 9999;
        printf("status unknown-vr %d\n", fmi2GetReal(c, &unknown, 1, &value));
        printf("status null-values %d\n", fmi2GetReal(c, &vr, 1, NULL));
        printf("status step-after-errors %d\n", fmi2DoStep(c, t, 1e-3, 1));
    }
    fmi2Terminate(c);
    fmi2FreeInstance(c);
    fmi2FreeInstance(c); /* a second free of the same pointer is ignored */
    dlclose(lib);
    printf("done\n");
    return 0;
}
