/*
 * fmu_core.h - the model-independent FMI 2.0 co-simulation layer of the native FMUs.
 *
 * fmu_core.c implements every fmi2 function with the error contract of the Python FMUs'
 * runtime (fmus/fmu_runtime.py and fmus/native/abufmu.c): call order, value references,
 * types, causalities and finiteness are checked, every refused call returns a status and
 * logs why, fmi2Fatal (out of memory) is latched, pointers to instances and FMU states are
 * checked against the live ones before use. A model (abuball_fmu.c, speedcontroller_fmu.c,
 * staircase_fmu.c) supplies only its data and the functions of AbuModel below; exactly one
 * model is linked into each binary.
 *
 * A model's data is a plain struct (no pointers), so an FMU state is a copy of it and its
 * serialization the same bytes behind a header (magic, version, model name, size).
 */
#ifndef ABU_FMU_CORE_H
#define ABU_FMU_CORE_H

#include <stddef.h>

typedef enum { ABU_REAL, ABU_INTEGER, ABU_BOOLEAN } AbuVarType;
typedef enum { ABU_PARAMETER, ABU_INPUT, ABU_OUTPUT } AbuCausality;

/* One variable; its value reference is its index in the model's table (as in the
 * modelDescription.xml the build writes). Parameters are fixed, inputs continuous. */
typedef struct {
    const char *name;
    AbuVarType type;
    AbuCausality causality;
} AbuVar;

typedef struct {
    const char *name; /* model identifier */
    const char *guid;
    const AbuVar *vars;
    unsigned n_vars;
    size_t data_size;
    void (*defaults)(void *data);
    void (*setup)(void *data, double start_time);
    /* 0, or 1 with a message (the instance stays in initialization mode). */
    int (*exit_init)(void *data, char *msg, int size);
    /* 0, or 1 with a message: fmi2Discard, nothing advanced. */
    int (*do_step)(void *data, double t, double h, char *msg, int size);
    double (*get_real)(void *data, unsigned vr);
    int (*get_int)(void *data, unsigned vr); /* Integer and Boolean variables */
    void (*set_real)(void *data, unsigned vr, double value);
    void (*set_int)(void *data, unsigned vr, int value);
    /* A deserialized state's data: 0 if consistent, else 1 with a message. May rebuild
     * derived fields. `initialized` is 1 when the state is past initialization. */
    int (*check)(void *data, int initialized, char *msg, int size);
} AbuModel;

/* Defined by the model's file. */
extern const AbuModel abu_model;

#endif
