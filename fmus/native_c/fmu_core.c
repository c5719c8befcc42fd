/*
 * fmu_core.c - the FMI 2.0 co-simulation functions of the native FMUs; see fmu_core.h.
 * Messages follow fmus/fmu_runtime.py so that a master sees the same texts from either build.
 */
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_core.h"

#ifdef _WIN32
#include <windows.h>
static SRWLOCK live_lock = SRWLOCK_INIT;
static void lock(void) { AcquireSRWLockExclusive(&live_lock); }
static void unlock(void) { ReleaseSRWLockExclusive(&live_lock); }
#else
#include <pthread.h>
static pthread_mutex_t live_lock = PTHREAD_MUTEX_INITIALIZER;
static void lock(void) { pthread_mutex_lock(&live_lock); }
static void unlock(void) { pthread_mutex_unlock(&live_lock); }
#endif

#define MAGIC 0x41425546u /* "ABUF": a live instance or state */
#define MAX_VR 100000     /* more value references in one call is not plausible */
#define TIME_TOLERANCE 1e-9
#define STATE_MAGIC "ABUFMUN1"
#define STATE_VERSION 1u
#define NAME_BYTES 32
/* magic, version, model name, data size, phase, time, last successful time */
#define HEADER_SIZE (8 + 4 + NAME_BYTES + 4 + 4 + 8 + 8)

enum { INSTANTIATED, INITIALIZATION, STEPPING, TERMINATED };
static const char *const PHASES[] = {"instantiated", "initialization mode", "step mode",
                                     "terminated"};

typedef struct State {
    uint32_t magic;
    struct State *next;
    int phase;
    double time, last_ok;
    unsigned char data[]; /* the model's data */
} State;

typedef struct Inst {
    uint32_t magic;
    struct Inst *next_live;
    fmi2CallbackFunctions cb;
    char *name;
    int logging_on, fatal, phase;
    double time, last_ok;
    State *states;
    unsigned char data[];
} Inst;

static Inst *live = NULL; /* every instance not yet freed: pointers are checked against it */

/* ------------------------------------------------------------------ logging */
static void log_text(const fmi2CallbackFunctions *cb, const char *name, fmi2Status status,
                     const char *text) {
    static const char *const categories[] = {"logAll", "logStatusWarning", "logStatusDiscard",
                                             "logStatusError", "logStatusFatal"};
    char safe[1400]; /* the message is a printf format for the logger: escape '%' */
    size_t n = 0;
    if (cb == NULL || cb->logger == NULL) return;
    for (const char *p = text; *p && n + 2 < sizeof safe; p++) {
        safe[n++] = *p;
        if (*p == '%') safe[n++] = '%';
    }
    safe[n] = 0;
    cb->logger(cb->componentEnvironment, name ? name : "", status, categories[status], safe);
}

static void logf_inst(Inst *c, fmi2Status status, const char *fmt, ...) {
    char text[1200];
    int prefix;
    va_list ap;
    if (status < fmi2Warning && !c->logging_on) return; /* as the Python runtime */
    prefix = snprintf(text, sizeof text, "%s '%s': ", abu_model.name, c->name);
    if (prefix < 0 || (size_t)prefix >= sizeof text) prefix = 0;
    va_start(ap, fmt);
    vsnprintf(text + prefix, sizeof text - (size_t)prefix, fmt, ap);
    va_end(ap);
    log_text(&c->cb, c->name, status, text);
}

static fmi2Status error(Inst *c, const char *fmt, const char *fn, const char *detail) {
    logf_inst(c, fmi2Error, fmt, fn, detail);
    return fmi2Error;
}

/* ------------------------------------------------------------------ instances */
static Inst *find_live(fmi2Component comp) {
    Inst *c;
    lock();
    for (c = live; c != NULL && c != (Inst *)comp; c = c->next_live) {}
    unlock();
    return c != NULL && c->magic == MAGIC ? c : NULL;
}

/* Common entry: NULL if the call must stop (status in *st), else the instance. */
static Inst *enter(fmi2Component comp, const char *fn, fmi2Status *st) {
    Inst *c = find_live(comp);
    *st = fmi2Error;
    if (c == NULL) return NULL; /* unknown or freed: nothing to log to */
    if (c->fatal) {
        logf_inst(c, fmi2Error, "%s: refused, the instance had a fatal error (free it)", fn);
        return NULL;
    }
    *st = fmi2OK;
    return c;
}

static fmi2Status require(Inst *c, const char *fn, int allowed_mask) {
    if (allowed_mask & (1 << c->phase)) return fmi2OK;
    logf_inst(c, fmi2Error, "%s is not allowed in %s", fn, PHASES[c->phase]);
    return fmi2Error;
}

static void *allocate(Inst *c, size_t size) { return c->cb.allocateMemory(1, size); }

static fmi2Status out_of_memory(Inst *c, const char *fn) {
    c->fatal = 1; /* as the Python runtime's MemoryError: latched */
    logf_inst(c, fmi2Fatal, "%s: out of memory (fatal: free the instance)", fn);
    return fmi2Fatal;
}

FMI2_Export const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
FMI2_Export const char *fmi2GetVersion(void) { return fmi2Version; }

static void instantiate_error(const fmi2CallbackFunctions *f, const char *name, const char *text) {
    char message[600];
    snprintf(message, sizeof message, "fmi2Instantiate: %s", text);
    log_text(f, name, fmi2Error, message);
}

FMI2_Export fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType,
                                          fmi2String fmuGUID, fmi2String fmuResourceLocation,
                                          const fmi2CallbackFunctions *functions,
                                          fmi2Boolean visible, fmi2Boolean loggingOn) {
    const char *name = instanceName ? instanceName : "";
    char text[400];
    (void)fmuResourceLocation; /* the native FMUs need no resources */
    (void)visible;
    if (functions == NULL) return NULL; /* no way to report anything */
    if (instanceName == NULL || instanceName[0] == 0) {
        instantiate_error(functions, name, "instanceName must be a non-empty string");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        instantiate_error(functions, name, "this FMU supports co-simulation only "
                          "(fmuType = fmi2CoSimulation)");
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, abu_model.guid) != 0) {
        snprintf(text, sizeof text, "GUID '%.100s' does not match the FMU's '%s'",
                 fmuGUID ? fmuGUID : "(null)", abu_model.guid);
        instantiate_error(functions, name, text);
        return NULL;
    }
    if (functions->allocateMemory == NULL || functions->freeMemory == NULL) {
        instantiate_error(functions, name, "allocateMemory and freeMemory are required");
        return NULL;
    }
    Inst *c = functions->allocateMemory(1, sizeof(Inst) + abu_model.data_size);
    char *copy = functions->allocateMemory(1, strlen(name) + 1);
    if (c == NULL || copy == NULL) {
        if (c) functions->freeMemory(c);
        if (copy) functions->freeMemory(copy);
        instantiate_error(functions, name, "out of memory");
        return NULL;
    }
    memset(c, 0, sizeof(Inst) + abu_model.data_size); /* also the padding: states are bytes */
    strcpy(copy, name);
    c->magic = MAGIC;
    c->cb = *functions;
    c->name = copy;
    c->logging_on = loggingOn != 0;
    c->phase = INSTANTIATED;
    abu_model.defaults(c->data);
    lock();
    c->next_live = live;
    live = c;
    unlock();
    return c;
}

static void free_states(Inst *c) {
    while (c->states != NULL) {
        State *s = c->states;
        c->states = s->next;
        s->magic = 0;
        c->cb.freeMemory(s);
    }
}

FMI2_Export void fmi2FreeInstance(fmi2Component comp) {
    Inst *c, **link;
    lock();
    for (link = &live; *link != NULL && *link != (Inst *)comp; link = &(*link)->next_live) {}
    c = *link;
    if (c != NULL) *link = c->next_live;
    unlock();
    if (c == NULL) return; /* unknown or already freed: ignored */
    free_states(c);
    c->magic = 0;
    c->cb.freeMemory(c->name);
    c->cb.freeMemory(c);
}

FMI2_Export fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn,
                                           size_t nCategories, const fmi2String categories[]) {
    fmi2Status st;
    Inst *c = enter(comp, "fmi2SetDebugLogging", &st);
    if (c == NULL) return st;
    if (nCategories > 0 && categories == NULL)
        return error(c, "%s: categories is NULL with nCategories > 0%s", "fmi2SetDebugLogging", "");
    c->logging_on = loggingOn != 0;
    return fmi2OK;
}

/* ------------------------------------------------------------------ life cycle */
FMI2_Export fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined,
                                           fmi2Real tolerance, fmi2Real startTime,
                                           fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    const char *fn = "fmi2SetupExperiment";
    fmi2Status st;
    Inst *c = enter(comp, fn, &st);
    if (c == NULL || (st = require(c, fn, 1 << INSTANTIATED)) != fmi2OK) return st;
    if (!isfinite(startTime)) {
        logf_inst(c, fmi2Error, "%s: startTime = %.17g s is not finite", fn, startTime);
        return fmi2Error;
    }
    if (stopTimeDefined && !(isfinite(stopTime) && stopTime >= startTime)) {
        logf_inst(c, fmi2Error, "%s: stopTime = %.17g s must be finite and >= startTime = "
                  "%.17g s", fn, stopTime, startTime);
        return fmi2Error;
    }
    if (toleranceDefined && !(isfinite(tolerance) && tolerance > 0.0)) {
        logf_inst(c, fmi2Error, "%s: tolerance = %.17g must be > 0", fn, tolerance);
        return fmi2Error;
    }
    abu_model.setup(c->data, startTime);
    c->time = c->last_ok = startTime;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    fmi2Status st;
    Inst *c = enter(comp, "fmi2EnterInitializationMode", &st);
    if (c == NULL || (st = require(c, "fmi2EnterInitializationMode", 1 << INSTANTIATED)))
        return st;
    c->phase = INITIALIZATION;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    fmi2Status st;
    char msg[600];
    Inst *c = enter(comp, "fmi2ExitInitializationMode", &st);
    if (c == NULL || (st = require(c, "fmi2ExitInitializationMode", 1 << INITIALIZATION)))
        return st;
    if (abu_model.exit_init(c->data, msg, sizeof msg))
        return error(c, "%s: %s", "fmi2ExitInitializationMode", msg);
    c->phase = STEPPING;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2Terminate(fmi2Component comp) {
    fmi2Status st;
    Inst *c = enter(comp, "fmi2Terminate", &st);
    if (c == NULL
        || (st = require(c, "fmi2Terminate", (1 << STEPPING) | (1 << INITIALIZATION))))
        return st;
    c->phase = TERMINATED;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2Reset(fmi2Component comp) {
    fmi2Status st;
    Inst *c = enter(comp, "fmi2Reset", &st);
    if (c == NULL) return st;
    memset(c->data, 0, abu_model.data_size);
    abu_model.defaults(c->data);
    c->phase = INSTANTIATED;
    c->time = c->last_ok = 0.0;
    return fmi2OK;
}

/* ------------------------------------------------------------------ stepping */
FMI2_Export fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real t, fmi2Real h,
                                  fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    const char *fn = "fmi2DoStep";
    char msg[600];
    fmi2Status st;
    Inst *c = enter(comp, fn, &st);
    (void)noSetFMUStatePriorToCurrentPoint;
    if (c == NULL || (st = require(c, fn, 1 << STEPPING))) return st;
    if (!(isfinite(t) && isfinite(h) && h >= 0.0)) {
        logf_inst(c, fmi2Error, "%s: currentCommunicationPoint = %.17g s and "
                  "communicationStepSize = %.17g s must be finite, the step >= 0", fn, t, h);
        return fmi2Error;
    }
    if (fabs(t - c->time) > TIME_TOLERANCE * (fabs(t) > 1.0 ? fabs(t) : 1.0)) {
        logf_inst(c, fmi2Error, "%s: currentCommunicationPoint = %.17g s but the FMU is at "
                  "t = %.17g s (restore a state to step from another time)", fn, t, c->time);
        return fmi2Error;
    }
    if (abu_model.do_step(c->data, t, h, msg, sizeof msg)) {
        c->last_ok = t;
        logf_inst(c, fmi2Error, "%s", msg); /* the Python slaves log it as an error too */
        return fmi2Discard;
    }
    c->time = c->last_ok = t + h;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2CancelStep(fmi2Component comp) {
    fmi2Status st;
    Inst *c = enter(comp, "fmi2CancelStep", &st);
    if (c == NULL) return st;
    return error(c, "%s: no step is pending (doStep never returns fmi2Pending)%s",
                 "fmi2CancelStep", "");
}

/* ------------------------------------------------------------------ status */
static Inst *status_enter(fmi2Component comp, const char *fn, const void *value,
                          fmi2Status *st) {
    Inst *c = enter(comp, fn, st);
    if (c != NULL && value == NULL) {
        *st = error(c, "%s: value is NULL%s", fn, "");
        return NULL;
    }
    return c;
}

static fmi2Status not_available(Inst *c, const char *what, int kind) {
    logf_inst(c, fmi2Warning, "%s status kind %d is not available (doStep is synchronous)",
              what, kind);
    return fmi2Discard;
}

FMI2_Export fmi2Status fmi2GetStatus(fmi2Component comp, const fmi2StatusKind s,
                                     fmi2Status *value) {
    fmi2Status st;
    Inst *c = status_enter(comp, "fmi2GetStatus", value, &st);
    return c == NULL ? st : not_available(c, "fmi2Status", (int)s);
}

FMI2_Export fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s,
                                         fmi2Real *value) {
    fmi2Status st;
    Inst *c = status_enter(comp, "fmi2GetRealStatus", value, &st);
    if (c == NULL) return st;
    if (s != fmi2LastSuccessfulTime) return not_available(c, "Real", (int)s);
    *value = c->last_ok;
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetIntegerStatus(fmi2Component comp, const fmi2StatusKind s,
                                            fmi2Integer *value) {
    fmi2Status st;
    Inst *c = status_enter(comp, "fmi2GetIntegerStatus", value, &st);
    return c == NULL ? st : not_available(c, "Integer", (int)s);
}

FMI2_Export fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s,
                                            fmi2Boolean *value) {
    fmi2Status st;
    Inst *c = status_enter(comp, "fmi2GetBooleanStatus", value, &st);
    if (c == NULL) return st;
    if (s != fmi2Terminated) return not_available(c, "Boolean", (int)s);
    *value = fmi2False; /* the FMU never asks to stop */
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetStringStatus(fmi2Component comp, const fmi2StatusKind s,
                                           fmi2String *value) {
    fmi2Status st;
    Inst *c = status_enter(comp, "fmi2GetStringStatus", value, &st);
    return c == NULL ? st : not_available(c, "String", (int)s);
}

static fmi2Status unsupported(fmi2Component comp, const char *fn) {
    fmi2Status st;
    Inst *c = enter(comp, fn, &st);
    if (c == NULL) return st;
    return error(c, "%s: not supported by this FMU (see its capability flags)%s", fn, "");
}

FMI2_Export fmi2Status fmi2GetDirectionalDerivative(fmi2Component c,
                                                    const fmi2ValueReference u[], size_t nu,
                                                    const fmi2ValueReference z[], size_t nz,
                                                    const fmi2Real dv[], fmi2Real dz[]) {
    (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz;
    return unsupported(c, "fmi2GetDirectionalDerivative");
}

FMI2_Export fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[],
                                                   size_t nvr, const fmi2Integer order[],
                                                   const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    return unsupported(c, "fmi2SetRealInputDerivatives");
}

FMI2_Export fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c,
                                                    const fmi2ValueReference vr[], size_t nvr,
                                                    const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    return unsupported(c, "fmi2GetRealOutputDerivatives");
}

/* ------------------------------------------------------------------ values */
static const char *const TYPE_NAMES[] = {"Real", "Integer", "Boolean", "String"};

/* The arrays and value references of a get/set call: 1 if usable, else 0 (logged). */
static int check_refs(Inst *c, const char *fn, const fmi2ValueReference vr[], size_t nvr,
                      const void *values, int type) {
    if (nvr > MAX_VR) {
        logf_inst(c, fmi2Error, "%s: nvr = %lu value references is not plausible", fn,
                  (unsigned long)nvr);
        return 0;
    }
    if (nvr > 0 && (vr == NULL || values == NULL)) {
        logf_inst(c, fmi2Error, "%s: %s is NULL with nvr = %lu", fn, vr == NULL ? "vr" : "value",
                  (unsigned long)nvr);
        return 0;
    }
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] < abu_model.n_vars && (int)abu_model.vars[vr[i]].type == type) continue;
        logf_inst(c, fmi2Error, "%s: value reference %u is not a %s variable of %s (%s%s)", fn,
                  vr[i], TYPE_NAMES[type], abu_model.name,
                  vr[i] < abu_model.n_vars ? abu_model.vars[vr[i]].name : "unknown",
                  vr[i] < abu_model.n_vars ? " has another type" : "");
        return 0;
    }
    return 1;
}

/* Whether variable vr may be set now (1), else 0 (logged). */
static int settable(Inst *c, const char *fn, fmi2ValueReference vr) {
    const AbuVar *v = &abu_model.vars[vr];
    if (v->causality == ABU_OUTPUT) {
        logf_inst(c, fmi2Error, "%s: '%s' is a output variable and cannot be set", fn, v->name);
        return 0;
    }
    if (c->phase == TERMINATED) {
        logf_inst(c, fmi2Error, "%s: '%s' cannot be set after fmi2Terminate", fn, v->name);
        return 0;
    }
    if (v->causality == ABU_PARAMETER && c->phase > INITIALIZATION) {
        logf_inst(c, fmi2Error, "%s: '%s' is a fixed parameter and cannot be set in %s (only "
                  "before fmi2ExitInitializationMode)", fn, v->name, PHASES[c->phase]);
        return 0;
    }
    return 1;
}

FMI2_Export fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                   fmi2Real value[]) {
    fmi2Status st;
    Inst *c = enter(comp, "fmi2GetReal", &st);
    if (c == NULL) return st;
    if (!check_refs(c, "fmi2GetReal", vr, nvr, value, ABU_REAL)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) value[i] = abu_model.get_real(c->data, vr[i]);
    return fmi2OK;
}

static fmi2Status get_ints(fmi2Component comp, const char *fn, const fmi2ValueReference vr[],
                           size_t nvr, fmi2Integer value[], int type) {
    fmi2Status st;
    Inst *c = enter(comp, fn, &st);
    if (c == NULL) return st;
    if (!check_refs(c, fn, vr, nvr, value, type)) return fmi2Error;
    for (size_t i = 0; i < nvr; i++) value[i] = abu_model.get_int(c->data, vr[i]);
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2GetInteger(fmi2Component comp, const fmi2ValueReference vr[],
                                      size_t nvr, fmi2Integer value[]) {
    return get_ints(comp, "fmi2GetInteger", vr, nvr, value, ABU_INTEGER);
}

FMI2_Export fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[],
                                      size_t nvr, fmi2Boolean value[]) {
    return get_ints(comp, "fmi2GetBoolean", vr, nvr, value, ABU_BOOLEAN);
}

FMI2_Export fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[],
                                     size_t nvr, fmi2String value[]) {
    fmi2Status st;
    Inst *c = enter(comp, "fmi2GetString", &st);
    if (c == NULL) return st;
    return check_refs(c, "fmi2GetString", vr, nvr, value, 3) ? fmi2OK : fmi2Error;
}

FMI2_Export fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                   const fmi2Real value[]) {
    const char *fn = "fmi2SetReal";
    fmi2Status st;
    size_t i;
    Inst *c = enter(comp, fn, &st);
    if (c == NULL) return st;
    if (!check_refs(c, fn, vr, nvr, value, ABU_REAL)) return fmi2Error;
    for (i = 0; i < nvr; i++) { /* check all before changing any */
        if (!settable(c, fn, vr[i])) return fmi2Error;
        if (!isfinite(value[i])) {
            logf_inst(c, fmi2Error, "%s: '%s' = %.17g is not a finite number", fn,
                      abu_model.vars[vr[i]].name, value[i]);
            return fmi2Error;
        }
    }
    for (i = 0; i < nvr; i++) abu_model.set_real(c->data, vr[i], value[i]);
    return fmi2OK;
}

static fmi2Status set_ints(fmi2Component comp, const char *fn, const fmi2ValueReference vr[],
                           size_t nvr, const fmi2Integer value[], int type) {
    fmi2Status st;
    size_t i;
    Inst *c = enter(comp, fn, &st);
    if (c == NULL) return st;
    if (!check_refs(c, fn, vr, nvr, value, type)) return fmi2Error;
    for (i = 0; i < nvr; i++)
        if (!settable(c, fn, vr[i])) return fmi2Error;
    for (i = 0; i < nvr; i++)
        abu_model.set_int(c->data, vr[i], type == ABU_BOOLEAN ? value[i] != 0 : value[i]);
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetInteger(fmi2Component comp, const fmi2ValueReference vr[],
                                      size_t nvr, const fmi2Integer value[]) {
    return set_ints(comp, "fmi2SetInteger", vr, nvr, value, ABU_INTEGER);
}

FMI2_Export fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[],
                                      size_t nvr, const fmi2Boolean value[]) {
    return set_ints(comp, "fmi2SetBoolean", vr, nvr, value, ABU_BOOLEAN);
}

FMI2_Export fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[],
                                     size_t nvr, const fmi2String value[]) {
    fmi2Status st;
    Inst *c = enter(comp, "fmi2SetString", &st);
    if (c == NULL) return st;
    return check_refs(c, "fmi2SetString", vr, nvr, value, 3) ? fmi2OK : fmi2Error;
}

/* ------------------------------------------------------------------ FMU states */
static State *find_state(Inst *c, fmi2FMUstate p) {
    State *s;
    for (s = c->states; s != NULL && s != (State *)p; s = s->next) {}
    return s;
}

/* The state to write for a get/deserialize: the host's own one if *p is ours, a new one if
 * *p is NULL. NULL with *st set on a foreign pointer or out of memory. */
static State *state_to_fill(Inst *c, const char *fn, fmi2FMUstate *p, fmi2Status *st) {
    State *s;
    if (*p != NULL) {
        if ((s = find_state(c, *p)) == NULL)
            *st = error(c, "%s: *FMUstate is neither NULL nor a state of this instance%s", fn, "");
        return s;
    }
    s = allocate(c, sizeof(State) + abu_model.data_size);
    if (s == NULL) {
        *st = out_of_memory(c, fn);
        return NULL;
    }
    s->magic = MAGIC;
    s->next = c->states;
    c->states = s;
    *p = s;
    return s;
}

FMI2_Export fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *FMUstate) {
    fmi2Status st;
    Inst *c = enter(comp, "fmi2GetFMUstate", &st);
    if (c == NULL) return st;
    if (FMUstate == NULL) return error(c, "%s: FMUstate is NULL%s", "fmi2GetFMUstate", "");
    State *s = state_to_fill(c, "fmi2GetFMUstate", FMUstate, &st);
    if (s == NULL) return st;
    s->phase = c->phase;
    s->time = c->time;
    s->last_ok = c->last_ok;
    memcpy(s->data, c->data, abu_model.data_size);
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate FMUstate) {
    fmi2Status st;
    Inst *c = enter(comp, "fmi2SetFMUstate", &st);
    if (c == NULL) return st;
    State *s = find_state(c, FMUstate);
    if (s == NULL)
        return error(c, "%s: not a state of this instance (unknown or freed pointer)%s",
                     "fmi2SetFMUstate", "");
    c->phase = s->phase;
    c->time = s->time;
    c->last_ok = s->last_ok;
    memcpy(c->data, s->data, abu_model.data_size);
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *FMUstate) {
    Inst *c = find_live(comp); /* no fatal check: freeing still frees */
    State **link;
    if (c == NULL) return fmi2Error;
    if (FMUstate == NULL || *FMUstate == NULL) return fmi2OK; /* nothing to free */
    for (link = &c->states; *link != NULL; link = &(*link)->next) {
        if (*link == (State *)*FMUstate) {
            State *s = *link;
            *link = s->next;
            s->magic = 0;
            c->cb.freeMemory(s);
            *FMUstate = NULL;
            return fmi2OK;
        }
    }
    return error(c, "%s: not a state of this instance (unknown or freed pointer)%s",
                 "fmi2FreeFMUstate", "");
}

static size_t serialized_size(void) { return HEADER_SIZE + abu_model.data_size; }

FMI2_Export fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate FMUstate,
                                                  size_t *size) {
    const char *fn = "fmi2SerializedFMUstateSize";
    fmi2Status st;
    Inst *c = enter(comp, fn, &st);
    if (c == NULL) return st;
    if (size == NULL) return error(c, "%s: size is NULL%s", fn, "");
    if (find_state(c, FMUstate) == NULL)
        return error(c, "%s: not a state of this instance (unknown or freed pointer)%s", fn, "");
    *size = serialized_size();
    return fmi2OK;
}

FMI2_Export fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate FMUstate,
                                             fmi2Byte serializedState[], size_t size) {
    const char *fn = "fmi2SerializeFMUstate";
    fmi2Status st;
    unsigned char *out = (unsigned char *)serializedState;
    uint32_t version = STATE_VERSION, data_size = (uint32_t)abu_model.data_size;
    int32_t phase;
    char name[NAME_BYTES] = {0};
    Inst *c = enter(comp, fn, &st);
    if (c == NULL) return st;
    State *s = find_state(c, FMUstate);
    if (s == NULL)
        return error(c, "%s: not a state of this instance (unknown or freed pointer)%s", fn, "");
    if (size != serialized_size() || serializedState == NULL) {
        logf_inst(c, fmi2Error, "%s: size = %lu (buffer %s), the state needs %lu bytes", fn,
                  (unsigned long)size, serializedState ? "given" : "NULL",
                  (unsigned long)serialized_size());
        return fmi2Error;
    }
    strncpy(name, abu_model.name, NAME_BYTES - 1);
    phase = s->phase;
    memcpy(out, STATE_MAGIC, 8);
    memcpy(out + 8, &version, 4);
    memcpy(out + 12, name, NAME_BYTES);
    memcpy(out + 12 + NAME_BYTES, &data_size, 4);
    memcpy(out + 16 + NAME_BYTES, &phase, 4);
    memcpy(out + 20 + NAME_BYTES, &s->time, 8);
    memcpy(out + 28 + NAME_BYTES, &s->last_ok, 8);
    memcpy(out + HEADER_SIZE, s->data, abu_model.data_size);
    return fmi2OK;
}

/* Why `in` (size bytes) is not a state of this model, or NULL; fills the parts. */
static const char *parse_state(const unsigned char *in, size_t size, int *phase, double *time,
                               double *last, void *data, char *msg, int msg_size) {
    uint32_t version, data_size;
    int32_t ph;
    char name[NAME_BYTES] = {0};
    strncpy(name, abu_model.name, NAME_BYTES - 1);
    if (size < HEADER_SIZE || memcmp(in, STATE_MAGIC, 8) != 0) return "no native state header";
    memcpy(&version, in + 8, 4);
    memcpy(&data_size, in + 12 + NAME_BYTES, 4);
    memcpy(&ph, in + 16 + NAME_BYTES, 4);
    memcpy(time, in + 20 + NAME_BYTES, 8);
    memcpy(last, in + 28 + NAME_BYTES, 8);
    if (version != STATE_VERSION) return "another version of the state format";
    if (memcmp(in + 12, name, NAME_BYTES) != 0) return "a state of another model";
    if (data_size != abu_model.data_size || size != serialized_size()) return "wrong size";
    if (ph < INSTANTIATED || ph > TERMINATED) return "unknown phase";
    if (!isfinite(*time) || !isfinite(*last)) return "time is not a finite number";
    memcpy(data, in + HEADER_SIZE, abu_model.data_size);
    *phase = ph;
    if (abu_model.check(data, ph >= STEPPING, msg, msg_size)) return msg;
    return NULL;
}

FMI2_Export fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp,
                                               const fmi2Byte serializedState[], size_t size,
                                               fmi2FMUstate *FMUstate) {
    const char *fn = "fmi2DeSerializeFMUstate", *why;
    char msg[400];
    int phase = 0;
    double time = 0.0, last = 0.0;
    fmi2Status st;
    Inst *c = enter(comp, fn, &st);
    if (c == NULL) return st;
    if (FMUstate == NULL || (size > 0 && serializedState == NULL))
        return error(c, "%s: %s is NULL", fn, FMUstate == NULL ? "FMUstate" : "serializedState");
    State *tmp = allocate(c, sizeof(State) + abu_model.data_size);
    if (tmp == NULL) return out_of_memory(c, fn);
    why = parse_state((const unsigned char *)serializedState, size, &phase, &time, &last,
                      tmp->data, msg, sizeof msg);
    if (why != NULL) {
        c->cb.freeMemory(tmp);
        logf_inst(c, fmi2Error, "%s: %lu bytes are not a serialized state of %s: %s", fn,
                  (unsigned long)size, abu_model.name, why);
        return fmi2Error;
    }
    State *s = state_to_fill(c, fn, FMUstate, &st);
    if (s != NULL) {
        s->phase = phase;
        s->time = time;
        s->last_ok = last;
        memcpy(s->data, tmp->data, abu_model.data_size);
    }
    c->cb.freeMemory(tmp);
    return s != NULL ? fmi2OK : st;
}

/* ------------------------------------------------------------------ model exchange: absent */
