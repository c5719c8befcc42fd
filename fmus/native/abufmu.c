/*
 * abufmu.c - the FMI 2.0 co-simulation binary of the toolkit's Python FMUs.
 *
 * Replaces pythonfmu 0.7's C++ export library (see docs/fmus.md, "The native layer"):
 *
 *  - loads the Python C API at run time (dlsym): from the host if it already runs Python,
 *    else by dlopen-ing libpython with RTLD_GLOBAL, so a non-Python host needs no LD_PRELOAD;
 *  - starts the interpreter only if nobody did, never finalises it (no exit-time crash);
 *  - forwards every fmi2 call to the FMU's Python runtime module (resources/<module>_rt.py),
 *    which checks call order, value references, times and states and answers with a status;
 *  - checks what it can itself (unknown or freed instance and state pointers, NULL arrays,
 *    absurd sizes) and latches fmi2Fatal: after a fatal error every call but
 *    fmi2FreeInstance returns fmi2Error, and freeing still frees.
 *
 * Build: cc -shared -fPIC -O2 -DABU_RUNTIME='"<module>_rt"' -DABU_GUID='"{...}"' abufmu.c -ldl
 * No Python headers are needed: the few API functions used are declared below.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <wchar.h>

#ifndef ABU_RUNTIME
#error "define ABU_RUNTIME (the Python runtime module of the FMU)"
#endif
#ifndef ABU_GUID
#error "define ABU_GUID (the FMU's guid)"
#endif

#define EXPORT __attribute__((visibility("default")))

/* ---- FMI 2.0 types (ABI of fmi2TypesPlatform.h / fmi2FunctionTypes.h) ---- */
typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;
typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef int fmi2StatusKind;
typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String,
                                   fmi2String, ...);
typedef struct {
    fmi2CallbackLogger logger;
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

/* ---- the part of the Python C API in use, resolved at run time ---- */
typedef struct _object PyObject;
typedef int PyGILState_STATE;
static struct {
    int (*Py_IsInitialized)(void);
    void (*Py_InitializeEx)(int);
    void *(*PyEval_SaveThread)(void);
    PyGILState_STATE (*PyGILState_Ensure)(void);
    void (*PyGILState_Release)(PyGILState_STATE);
    const char *(*Py_GetVersion)(void);
    void (*Py_SetPythonHome)(const wchar_t *);
    wchar_t *(*Py_DecodeLocale)(const char *, size_t *);
    PyObject *(*PyImport_ImportModule)(const char *);
    PyObject *(*PyImport_GetModuleDict)(void);
    PyObject *(*PyDict_GetItemString)(PyObject *, const char *);
    PyObject *(*PySys_GetObject)(const char *);
    PyObject *(*PyObject_CallMethod)(PyObject *, const char *, const char *, ...);
    PyObject *(*PyObject_Str)(PyObject *);
    long (*PyLong_AsLong)(PyObject *);
    double (*PyFloat_AsDouble)(PyObject *);
    PyObject *(*PyTuple_GetItem)(PyObject *, ssize_t);
    ssize_t (*PyTuple_Size)(PyObject *);
    PyObject *(*PyList_New)(ssize_t);
    int (*PyList_SetItem)(PyObject *, ssize_t, PyObject *);
    int (*PyList_Insert)(PyObject *, ssize_t, PyObject *);
    PyObject *(*PyList_GetItem)(PyObject *, ssize_t);
    ssize_t (*PyList_Size)(PyObject *);
    PyObject *(*PyBytes_FromStringAndSize)(const char *, ssize_t);
    char *(*PyBytes_AsString)(PyObject *);
    ssize_t (*PyBytes_Size)(PyObject *);
    PyObject *(*PyUnicode_FromString)(const char *);
    const char *(*PyUnicode_AsUTF8)(PyObject *);
    PyObject *(*PyErr_Occurred)(void);
    void (*PyErr_Fetch)(PyObject **, PyObject **, PyObject **);
    void (*PyErr_Clear)(void);
    void (*Py_IncRef)(PyObject *);
    void (*Py_DecRef)(PyObject *);
    PyObject *None;
} py;

static pthread_mutex_t lock = PTHREAD_MUTEX_INITIALIZER;
static int py_ready = 0;
static char py_problem[1024];

#define MAX_VR 1000000u /* more value references in one call is a host error */
#define MAGIC 0xABF2C0DEu
#define LOG_PENDING 0x100

typedef struct {
    uint32_t magic;
    PyObject *obj;
} State;

typedef struct {
    uint32_t magic;
    char *name;
    fmi2CallbackFunctions cb;
    PyObject *obj;      /* the runtime's Instance */
    PyObject *strings;  /* keeps the last fmi2GetString results alive */
    int fatal;
    State **states;
    size_t n_states, cap_states;
} Inst;

static Inst **live = NULL; /* every instance not yet freed: pointers are checked against it */
static size_t n_live = 0, cap_live = 0;

/* ------------------------------------------------------------------ logging */
static void log_raw(const fmi2CallbackFunctions *cb, const char *name, fmi2Status status,
                    const char *category, const char *message) {
    if (cb == NULL || cb->logger == NULL) return;
    /* The message is the format string of a printf-like logger: escape '%'. */
    size_t n = strlen(message), extra = 0;
    for (size_t i = 0; i < n; i++) extra += message[i] == '%';
    char *safe = malloc(n + extra + 1);
    if (safe == NULL) return;
    char *p = safe;
    for (size_t i = 0; i < n; i++) {
        *p++ = message[i];
        if (message[i] == '%') *p++ = '%';
    }
    *p = 0;
    cb->logger(cb->componentEnvironment, name ? name : "", status, category, safe);
    free(safe);
}

static void logf_inst(Inst *c, fmi2Status status, const char *fmt, ...) {
    char buffer[1200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(buffer, sizeof buffer, fmt, ap);
    va_end(ap);
    log_raw(&c->cb, c->name, status, status >= fmi2Error ? "logStatusError" : "logStatusWarning",
            buffer);
}

/* ------------------------------------------------------------------ Python */
static void *find_symbol(void *handle, const char *name) {
    return handle ? dlsym(handle, name) : dlsym(RTLD_DEFAULT, name);
}

static int resolve_api(void *handle) {
#define GET(f) if ((*(void **)&py.f = find_symbol(handle, #f)) == NULL) return 0;
    GET(Py_IsInitialized) GET(Py_InitializeEx) GET(PyEval_SaveThread) GET(PyGILState_Ensure)
    GET(PyGILState_Release) GET(Py_GetVersion) GET(PyImport_ImportModule)
    GET(PyImport_GetModuleDict) GET(PyDict_GetItemString) GET(PySys_GetObject)
    GET(PyObject_CallMethod) GET(PyObject_Str) GET(PyLong_AsLong) GET(PyFloat_AsDouble)
    GET(PyTuple_GetItem) GET(PyTuple_Size) GET(PyList_New) GET(PyList_SetItem)
    GET(PyList_Insert) GET(PyList_GetItem) GET(PyList_Size) GET(PyBytes_FromStringAndSize)
    GET(PyBytes_AsString) GET(PyBytes_Size) GET(PyUnicode_FromString) GET(PyUnicode_AsUTF8)
    GET(PyErr_Occurred) GET(PyErr_Fetch) GET(PyErr_Clear) GET(Py_IncRef) GET(Py_DecRef)
#undef GET
    *(void **)&py.Py_SetPythonHome = find_symbol(handle, "Py_SetPythonHome");
    *(void **)&py.Py_DecodeLocale = find_symbol(handle, "Py_DecodeLocale");
    py.None = find_symbol(handle, "_Py_NoneStruct");
    return py.None != NULL;
}

static int is_file(const char *path) {
    struct stat st;
    return stat(path, &st) == 0 && S_ISREG(st.st_mode);
}

/* resources/abufmu_python.txt: line 1 libpython, line 2 its home (written at build time). */
static void read_python_txt(const char *resources, char *lib, char *home, size_t size) {
    char path[4096];
    lib[0] = home[0] = 0;
    snprintf(path, sizeof path, "%s/abufmu_python.txt", resources);
    FILE *f = fopen(path, "r");
    if (f == NULL) return;
    if (fgets(lib, (int)size, f) && fgets(home, (int)size, f)) { /* both lines read */ }
    fclose(f);
    lib[strcspn(lib, "\r\n")] = 0;
    home[strcspn(home, "\r\n")] = 0;
}

/* Make the Python C API usable: the host's interpreter, or libpython loaded and started. */
static int ensure_python(const char *resources) {
    pthread_mutex_lock(&lock);
    if (py_ready) { pthread_mutex_unlock(&lock); return 1; }
    char lib[2048], home[2048];
    read_python_txt(resources, lib, home, sizeof lib);
    int ok = resolve_api(NULL); /* a Python host (or an FMU before us) made it global */
    if (!ok) {
        const char *candidates[4] = {getenv("ABUFMU_LIBPYTHON"), lib, NULL, NULL};
        char soname[64] = "";
        const char *base = strrchr(lib, '/');
        if (base && strlen(base + 1) < sizeof soname) { strcpy(soname, base + 1); candidates[2] = soname; }
        candidates[3] = "libpython3.so";
        for (int i = 0; i < 4 && !ok; i++) {
            if (candidates[i] == NULL || candidates[i][0] == 0) continue;
            void *handle = dlopen(candidates[i], RTLD_NOW | RTLD_GLOBAL);
            if (handle != NULL) ok = resolve_api(handle);
        }
        if (!ok) {
            snprintf(py_problem, sizeof py_problem,
                     "cannot load libpython (tried $ABUFMU_LIBPYTHON, '%.500s', its soname, "
                     "libpython3.so): %.300s", lib, dlerror());
            pthread_mutex_unlock(&lock);
            return 0;
        }
    }
    if (!py.Py_IsInitialized()) {
        /* Py_InitializeEx aborts the process if it cannot find the standard library:
           check first, and point it at the home recorded at build time. */
        const char *env_home = getenv("PYTHONHOME");
        const char *use = (env_home && env_home[0]) ? env_home : home;
        int major = 3, minor = 0;
        sscanf(py.Py_GetVersion(), "%d.%d", &major, &minor);
        char probe[4200];
        snprintf(probe, sizeof probe, "%s/lib/python%d.%d/os.py", use, major, minor);
        if (use[0] == 0 || !is_file(probe)) {
            snprintf(py_problem, sizeof py_problem,
                     "cannot find the Python %d.%d standard library (looked for '%.900s'); "
                     "set PYTHONHOME", major, minor, probe);
            pthread_mutex_unlock(&lock);
            return 0;
        }
        if ((env_home == NULL || env_home[0] == 0) && py.Py_SetPythonHome && py.Py_DecodeLocale) {
            wchar_t *w = py.Py_DecodeLocale(home, NULL); /* kept: Python keeps the pointer */
            if (w) py.Py_SetPythonHome(w);
        }
        py.Py_InitializeEx(0); /* no signal handlers: the host owns them */
        py.PyEval_SaveThread(); /* release the GIL; it is never finalised (see docs) */
    }
    py_ready = 1;
    pthread_mutex_unlock(&lock);
    return 1;
}

/* Text of the pending Python exception (cleared), into buffer. */
static void exception_text(char *buffer, size_t size) {
    PyObject *type = NULL, *value = NULL, *tb = NULL;
    snprintf(buffer, size, "unknown Python error");
    if (!py.PyErr_Occurred()) return;
    py.PyErr_Fetch(&type, &value, &tb);
    if (value != NULL) {
        PyObject *s = py.PyObject_Str(value);
        const char *text = s ? py.PyUnicode_AsUTF8(s) : NULL;
        if (text) snprintf(buffer, size, "%s", text);
        if (s) py.Py_DecRef(s);
    }
    py.PyErr_Clear();
    if (type) py.Py_DecRef(type);
    if (value) py.Py_DecRef(value);
    if (tb) py.Py_DecRef(tb);
}

/* The runtime module: imported once per process with resources on sys.path only meanwhile. */
static PyObject *runtime_module(const char *resources, char *problem, size_t size) {
    PyObject *mod = py.PyDict_GetItemString(py.PyImport_GetModuleDict(), ABU_RUNTIME);
    if (mod != NULL) { py.Py_IncRef(mod); return mod; }
    PyObject *path = py.PySys_GetObject("path");
    PyObject *entry = py.PyUnicode_FromString(resources);
    if (path == NULL || entry == NULL || py.PyList_Insert(path, 0, entry) != 0) {
        exception_text(problem, size);
        if (entry) py.Py_DecRef(entry);
        return NULL;
    }
    mod = py.PyImport_ImportModule(ABU_RUNTIME);
    if (mod == NULL) exception_text(problem, size);
    PyObject *r = py.PyObject_CallMethod(path, "remove", "(O)", entry);
    if (r) py.Py_DecRef(r); else py.PyErr_Clear();
    py.Py_DecRef(entry);
    return mod;
}

/* ------------------------------------------------------------------ instances */
static int is_live(Inst *c) {
    int found = 0;
    pthread_mutex_lock(&lock);
    for (size_t i = 0; i < n_live && !found; i++) found = live[i] == c;
    pthread_mutex_unlock(&lock);
    return found && c->magic == MAGIC;
}

static void forget(Inst *c) {
    pthread_mutex_lock(&lock);
    for (size_t i = 0; i < n_live; i++)
        if (live[i] == c) { live[i] = live[--n_live]; break; }
    pthread_mutex_unlock(&lock);
}

/* Status of a runtime call's result; *payload = second tuple item (borrowed). Logs drained. */
static fmi2Status finish(Inst *c, const char *fn, PyObject *result, PyObject **payload) {
    if (payload) *payload = NULL;
    if (result == NULL) {
        char text[1000];
        exception_text(text, sizeof text);
        c->fatal = 1;
        logf_inst(c, fmi2Fatal, "%s: internal error of the FMU runtime: %s", fn, text);
        return fmi2Fatal;
    }
    /* Every runtime method returns (status [| LOG_PENDING], payload or None). */
    PyObject *code = py.PyTuple_Size(result) == 2 ? py.PyTuple_GetItem(result, 0) : NULL;
    if (code != NULL && payload) *payload = py.PyTuple_GetItem(result, 1);
    long value = code ? py.PyLong_AsLong(code) : -1;
    if (value == -1) {
        py.PyErr_Clear();
        if (payload) *payload = NULL;
        c->fatal = 1;
        logf_inst(c, fmi2Fatal, "%s: internal error: malformed answer of the FMU runtime", fn);
        return fmi2Fatal;
    }
    if (value & LOG_PENDING) {
        PyObject *logs = py.PyObject_CallMethod(c->obj, "drain_logs", NULL);
        ssize_t n = logs ? py.PyList_Size(logs) : 0;
        for (ssize_t i = 0; i < n; i++) {
            PyObject *item = py.PyList_GetItem(logs, i);
            PyObject *cat = py.PyTuple_GetItem(item, 1), *msg = py.PyTuple_GetItem(item, 2);
            const char *cs = cat ? py.PyUnicode_AsUTF8(cat) : NULL;
            const char *ms = msg ? py.PyUnicode_AsUTF8(msg) : NULL;
            if (ms) log_raw(&c->cb, c->name, (fmi2Status)py.PyLong_AsLong(py.PyTuple_GetItem(item, 0)),
                            cs ? cs : "logAll", ms);
            py.PyErr_Clear();
        }
        if (logs) py.Py_DecRef(logs); else py.PyErr_Clear();
    }
    int logged = (value & LOG_PENDING) != 0;
    value &= 0xff;
    if (value < fmi2OK || value > fmi2Pending) value = fmi2Fatal;
    if (value == fmi2Fatal) {
        c->fatal = 1;
        if (!logged) logf_inst(c, fmi2Fatal, "%s: fatal error in the FMU runtime", fn);
    }
    return (fmi2Status)value;
}

/* finish() for a result this call owns and does not read: released here. */
static fmi2Status finish_owned(Inst *c, const char *fn, PyObject *result) {
    fmi2Status st = finish(c, fn, result, NULL);
    if (result) py.Py_DecRef(result);
    return st;
}

/* Common entry checks. Returns 0 if the call may proceed, else the status to return. */
static int enter(Inst *c, const char *fn, fmi2Status *status) {
    if (c == NULL || !is_live(c)) { *status = fmi2Error; return 1; } /* nothing to log to */
    if (c->fatal) {
        logf_inst(c, fmi2Error, "%s: refused, the instance had a fatal error (free it)", fn);
        *status = fmi2Error;
        return 1;
    }
    if (!py.Py_IsInitialized()) { /* a Python host that has already finalised its interpreter */
        logf_inst(c, fmi2Error, "%s: refused, the Python interpreter has been finalised", fn);
        *status = fmi2Error;
        return 1;
    }
    return 0;
}

#define BEGIN(fn)                                                    \
    Inst *c = (Inst *)comp;                                          \
    fmi2Status st;                                                   \
    if (enter(c, fn, &st)) return st;                                \
    PyGILState_STATE gil = py.PyGILState_Ensure();
#define END() py.PyGILState_Release(gil); return st;

static int check_arrays(Inst *c, const char *fn, size_t nvr, const void *vr, const void *values) {
    if (nvr > MAX_VR) {
        logf_inst(c, fmi2Error, "%s: nvr = %zu value references is not plausible", fn, nvr);
        return 0;
    }
    if (nvr > 0 && (vr == NULL || values == NULL)) {
        logf_inst(c, fmi2Error, "%s: %s is NULL with nvr = %zu", fn, vr == NULL ? "vr" : "value", nvr);
        return 0;
    }
    return 1;
}

/* ------------------------------------------------------------------ FMI: instances */
EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

static int resources_path(const char *uri, char *out, size_t size) {
    out[0] = 0;
    if (uri != NULL && strncmp(uri, "file:", 5) == 0) {
        const char *p = uri + 5;
        if (strncmp(p, "///", 3) == 0) p += 2;
        else if (strncmp(p, "//localhost/", 12) == 0) p += 11;
        else if (strncmp(p, "//", 2) == 0) p = NULL; /* another host: not ours */
        size_t n = 0;
        for (; p && *p && n + 1 < size; p++) {
            if (p[0] == '%' && p[1] && p[2]) {
                char hex[3] = {p[1], p[2], 0};
                out[n++] = (char)strtol(hex, NULL, 16);
                p += 2;
            } else {
                out[n++] = *p;
            }
        }
        out[n] = 0;
        while (n > 1 && out[n - 1] == '/') out[--n] = 0;
        char probe[4200];
        snprintf(probe, sizeof probe, "%s/%s.py", out, ABU_RUNTIME);
        if (is_file(probe)) return 1;
    }
    /* Fall back to the FMU layout: <fmu>/binaries/linux64/<id>.so -> <fmu>/resources. */
    Dl_info info;
    if (dladdr((void *)&fmi2GetVersion, &info) && info.dli_fname) {
        char *copy = strdup(info.dli_fname);
        for (int i = 0; i < 3 && copy; i++) {
            char *slash = strrchr(copy, '/');
            if (slash) *slash = 0;
        }
        if (copy) {
            snprintf(out, size, "%s/resources", copy);
            free(copy);
            char probe[4200];
            snprintf(probe, sizeof probe, "%s/%s.py", out, ABU_RUNTIME);
            return is_file(probe);
        }
    }
    return 0;
}

static void destroy(Inst *c);

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                     fmi2String fmuResourceLocation,
                                     const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                                     fmi2Boolean loggingOn) {
    const char *name = instanceName ? instanceName : "";
    char message[1400];
    if (functions == NULL) return NULL; /* no way to report anything */
    if (instanceName == NULL || instanceName[0] == 0) {
        log_raw(functions, name, fmi2Error, "logStatusError",
                "fmi2Instantiate: instanceName must be a non-empty string");
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        log_raw(functions, name, fmi2Error, "logStatusError",
                "fmi2Instantiate: this FMU supports co-simulation only (fmuType = fmi2CoSimulation)");
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, ABU_GUID) != 0) {
        snprintf(message, sizeof message, "fmi2Instantiate: GUID '%s' does not match the FMU's '%s'",
                 fmuGUID ? fmuGUID : "(null)", ABU_GUID);
        log_raw(functions, name, fmi2Error, "logStatusError", message);
        return NULL;
    }
    char resources[4096];
    if (!resources_path(fmuResourceLocation, resources, sizeof resources)) {
        snprintf(message, sizeof message, "fmi2Instantiate: no runtime %s.py under the resource "
                 "location '%s'", ABU_RUNTIME, fmuResourceLocation ? fmuResourceLocation : "(null)");
        log_raw(functions, name, fmi2Error, "logStatusError", message);
        return NULL;
    }
    if (!ensure_python(resources)) {
        snprintf(message, sizeof message, "fmi2Instantiate: %s", py_problem);
        log_raw(functions, name, fmi2Error, "logStatusError", message);
        return NULL;
    }
    Inst *c = calloc(1, sizeof(Inst));
    if (c == NULL || (c->name = strdup(name)) == NULL) {
        free(c);
        return NULL;
    }
    c->magic = MAGIC;
    c->cb = *functions;
    PyGILState_STATE gil = py.PyGILState_Ensure();
    PyObject *mod = runtime_module(resources, message, sizeof message);
    PyObject *result = mod ? py.PyObject_CallMethod(mod, "instantiate", "(ssii)", name, resources,
                                                    (int)visible, (int)loggingOn) : NULL;
    if (mod) py.Py_DecRef(mod);
    if (mod && result == NULL) exception_text(message, sizeof message);
    PyObject *obj = result ? py.PyTuple_GetItem(result, 1) : NULL;
    long code = result ? py.PyLong_AsLong(py.PyTuple_GetItem(result, 0)) : fmi2Fatal;
    if (obj == NULL || code != fmi2OK) {
        const char *text = obj ? py.PyUnicode_AsUTF8(obj) : NULL;
        char full[1500];
        snprintf(full, sizeof full, "fmi2Instantiate: %s", text ? text : message);
        py.PyErr_Clear();
        log_raw(functions, name, fmi2Error, "logStatusError", full);
        if (result) py.Py_DecRef(result);
        py.PyGILState_Release(gil);
        free(c->name);
        free(c);
        return NULL;
    }
    py.Py_IncRef(obj);
    c->obj = obj;
    py.Py_DecRef(result);
    py.PyGILState_Release(gil);
    pthread_mutex_lock(&lock);
    if (n_live == cap_live) {
        size_t cap = cap_live ? 2 * cap_live : 16;
        Inst **grown = realloc(live, cap * sizeof(Inst *));
        if (grown == NULL) { pthread_mutex_unlock(&lock); destroy(c); return NULL; }
        live = grown;
        cap_live = cap;
    }
    live[n_live++] = c;
    pthread_mutex_unlock(&lock);
    return c;
}


EXPORT void fmi2FreeInstance(fmi2Component comp) {
    Inst *c = (Inst *)comp;
    if (c == NULL || !is_live(c)) return; /* unknown or already freed: nothing to do */
    forget(c);
    destroy(c);
}

static void destroy(Inst *c) {
    if (!py.Py_IsInitialized()) { /* the host finalised Python: free only our own memory */
        for (size_t i = 0; i < c->n_states; i++) free(c->states[i]);
        free(c->states);
        free(c->name);
        c->magic = 0;
        free(c);
        return;
    }
    PyGILState_STATE gil = py.PyGILState_Ensure();
    for (size_t i = 0; i < c->n_states; i++) {
        py.Py_DecRef(c->states[i]->obj);
        c->states[i]->magic = 0;
        free(c->states[i]);
    }
    if (c->strings) py.Py_DecRef(c->strings);
    if (c->obj) {
        PyObject *r = py.PyObject_CallMethod(c->obj, "free", NULL);
        if (r) py.Py_DecRef(r); else py.PyErr_Clear();
        py.Py_DecRef(c->obj);
    }
    py.PyGILState_Release(gil);
    free(c->states);
    free(c->name);
    c->magic = 0;
    free(c);
}

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories,
                                      const fmi2String categories[]) {
    BEGIN("fmi2SetDebugLogging")
    if (nCategories > 0 && categories == NULL) {
        logf_inst(c, fmi2Error, "fmi2SetDebugLogging: categories is NULL with nCategories = %zu", nCategories);
        st = fmi2Error;
    } else {
        st = finish_owned(c, "fmi2SetDebugLogging",
                          py.PyObject_CallMethod(c->obj, "set_debug_logging", "(i)", (int)loggingOn));
    }
    END()
}

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                                      fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    BEGIN("fmi2SetupExperiment")
    st = finish_owned(c, "fmi2SetupExperiment",
                      py.PyObject_CallMethod(c->obj, "setup_experiment", "(iddid)", (int)toleranceDefined,
                                             tolerance, startTime, (int)stopTimeDefined, stopTime));
    END()
}

#define SIMPLE(fminame, method)                                                           \
    EXPORT fmi2Status fminame(fmi2Component comp) {                                       \
        BEGIN(#fminame)                                                                   \
        st = finish_owned(c, #fminame, py.PyObject_CallMethod(c->obj, method, NULL));     \
        END()                                                                             \
    }
SIMPLE(fmi2EnterInitializationMode, "enter_initialization_mode")
SIMPLE(fmi2ExitInitializationMode, "exit_initialization_mode")
/* fmi2Terminate after the host's interpreter has finalised (libcosimpy's destructors run
 * after Python's shutdown): the instance's Python side is gone with the interpreter and there
 * is nothing left to end, so it succeeds without a message. Every call that would need
 * Python still refuses (enter(): fmi2Error and a logged message). */
EXPORT fmi2Status fmi2Terminate(fmi2Component comp) {
    Inst *inst = (Inst *)comp;
    if (inst != NULL && is_live(inst) && !inst->fatal && !py.Py_IsInitialized()) return fmi2OK;
    BEGIN("fmi2Terminate")
    st = finish_owned(c, "fmi2Terminate", py.PyObject_CallMethod(c->obj, "terminate", NULL));
    END()
}
SIMPLE(fmi2Reset, "reset")
SIMPLE(fmi2CancelStep, "cancel_step")

/* ------------------------------------------------------------------ FMI: values */
static fmi2Status get_values(Inst *c, const char *fn, const char *method, const fmi2ValueReference vr[],
                             size_t nvr, void *values, size_t item) {
    if (!check_arrays(c, fn, nvr, vr, values)) return fmi2Error;
    PyObject *vrs = py.PyBytes_FromStringAndSize((const char *)vr, (ssize_t)(nvr * sizeof *vr));
    if (vrs == NULL) return finish(c, fn, NULL, NULL);
    PyObject *payload, *result = py.PyObject_CallMethod(c->obj, method, "(O)", vrs);
    py.Py_DecRef(vrs);
    fmi2Status st = finish(c, fn, result, &payload);
    if (st <= fmi2Warning) {
        if (payload == NULL || py.PyBytes_Size(payload) != (ssize_t)(nvr * item)) {
            py.PyErr_Clear();
            c->fatal = 1;
            logf_inst(c, fmi2Fatal, "%s: the runtime returned a malformed result", fn);
            st = fmi2Fatal;
        } else if (nvr > 0) {
            memcpy(values, py.PyBytes_AsString(payload), nvr * item);
        }
    }
    if (result) py.Py_DecRef(result);
    return st;
}

static fmi2Status set_values(Inst *c, const char *fn, const char *method, const fmi2ValueReference vr[],
                             size_t nvr, const void *values, size_t item) {
    if (!check_arrays(c, fn, nvr, vr, values)) return fmi2Error;
    PyObject *vrs = py.PyBytes_FromStringAndSize((const char *)vr, (ssize_t)(nvr * sizeof *vr));
    PyObject *vals = py.PyBytes_FromStringAndSize(nvr ? (const char *)values : "", (ssize_t)(nvr * item));
    PyObject *result = (vrs && vals) ? py.PyObject_CallMethod(c->obj, method, "(OO)", vrs, vals) : NULL;
    if (vrs) py.Py_DecRef(vrs);
    if (vals) py.Py_DecRef(vals);
    fmi2Status st = finish(c, fn, result, NULL);
    if (result) py.Py_DecRef(result);
    return st;
}

#define GETTER(fminame, method, ctype)                                                              \
    EXPORT fmi2Status fminame(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, ctype value[]) { \
        BEGIN(#fminame)                                                                             \
        st = get_values(c, #fminame, method, vr, nvr, value, sizeof(ctype));                        \
        END()                                                                                       \
    }
#define SETTER(fminame, method, ctype)                                                              \
    EXPORT fmi2Status fminame(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const ctype value[]) { \
        BEGIN(#fminame)                                                                             \
        st = set_values(c, #fminame, method, vr, nvr, value, sizeof(ctype));                        \
        END()                                                                                       \
    }
GETTER(fmi2GetReal, "get_real", fmi2Real)
GETTER(fmi2GetInteger, "get_integer", fmi2Integer)
GETTER(fmi2GetBoolean, "get_boolean", fmi2Boolean)
SETTER(fmi2SetReal, "set_real", fmi2Real)
SETTER(fmi2SetInteger, "set_integer", fmi2Integer)
SETTER(fmi2SetBoolean, "set_boolean", fmi2Boolean)

EXPORT fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    BEGIN("fmi2GetString")
    if (!check_arrays(c, "fmi2GetString", nvr, vr, value)) { st = fmi2Error; END() }
    PyObject *vrs = py.PyBytes_FromStringAndSize((const char *)vr, (ssize_t)(nvr * sizeof *vr));
    PyObject *payload, *result = vrs ? py.PyObject_CallMethod(c->obj, "get_string", "(O)", vrs) : NULL;
    if (vrs) py.Py_DecRef(vrs);
    st = finish(c, "fmi2GetString", result, &payload);
    if (st <= fmi2Warning) {
        if (payload == NULL || py.PyList_Size(payload) != (ssize_t)nvr) {
            py.PyErr_Clear();
            c->fatal = 1;
            logf_inst(c, fmi2Fatal, "fmi2GetString: the runtime returned a malformed result");
            st = fmi2Fatal;
        } else {
            if (c->strings) py.Py_DecRef(c->strings);
            py.Py_IncRef(payload);
            c->strings = payload; /* the char pointers stay valid until the next call */
            for (size_t i = 0; i < nvr; i++) value[i] = py.PyBytes_AsString(py.PyList_GetItem(payload, (ssize_t)i));
        }
    }
    if (result) py.Py_DecRef(result);
    END()
}

EXPORT fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    BEGIN("fmi2SetString")
    if (!check_arrays(c, "fmi2SetString", nvr, vr, value)) { st = fmi2Error; END() }
    PyObject *vrs = py.PyBytes_FromStringAndSize((const char *)vr, (ssize_t)(nvr * sizeof *vr));
    PyObject *list = py.PyList_New((ssize_t)nvr);
    for (size_t i = 0; list && i < nvr; i++) {
        PyObject *item = value[i] ? py.PyBytes_FromStringAndSize(value[i], (ssize_t)strlen(value[i])) : NULL;
        if (item == NULL) { py.Py_IncRef(py.None); item = py.None; }
        py.PyList_SetItem(list, (ssize_t)i, item);
    }
    PyObject *result = (vrs && list) ? py.PyObject_CallMethod(c->obj, "set_string", "(OO)", vrs, list) : NULL;
    if (vrs) py.Py_DecRef(vrs);
    if (list) py.Py_DecRef(list);
    st = finish(c, "fmi2SetString", result, NULL);
    if (result) py.Py_DecRef(result);
    END()
}

/* ------------------------------------------------------------------ FMI: stepping, status */
EXPORT fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real currentCommunicationPoint,
                             fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    BEGIN("fmi2DoStep")
    PyObject *result = py.PyObject_CallMethod(c->obj, "do_step", "(ddi)", currentCommunicationPoint,
                                              communicationStepSize, (int)noSetFMUStatePriorToCurrentPoint);
    st = finish(c, "fmi2DoStep", result, NULL);
    if (result) py.Py_DecRef(result);
    END()
}

static fmi2Status status_query(fmi2Component comp, const char *fn, const char *method, fmi2StatusKind s,
                               void *value, int kind) {
    BEGIN(fn)
    if (value == NULL) {
        logf_inst(c, fmi2Error, "%s: value is NULL", fn);
        st = fmi2Error;
        END()
    }
    PyObject *payload, *result = py.PyObject_CallMethod(c->obj, method, "(i)", (int)s);
    st = finish(c, fn, result, &payload);
    if (st == fmi2OK && payload != NULL) {
        if (kind == 0) *(fmi2Real *)value = py.PyFloat_AsDouble(payload);
        else if (kind == 1) *(fmi2Integer *)value = (fmi2Integer)py.PyLong_AsLong(payload);
        else if (kind == 2) *(fmi2Boolean *)value = (fmi2Boolean)py.PyLong_AsLong(payload);
        else *(fmi2String *)value = "";
        py.PyErr_Clear();
    }
    if (result) py.Py_DecRef(result);
    END()
}

EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    return status_query(c, "fmi2GetStatus", "get_status", s, value, 1);
}
EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    return status_query(c, "fmi2GetRealStatus", "get_real_status", s, value, 0);
}
EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    return status_query(c, "fmi2GetIntegerStatus", "get_status", s, value, 1);
}
EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    return status_query(c, "fmi2GetBooleanStatus", "get_boolean_status", s, value, 2);
}
EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    return status_query(c, "fmi2GetStringStatus", "get_status", s, value, 3);
}

static fmi2Status unsupported(fmi2Component comp, const char *fn) {
    BEGIN(fn)
    logf_inst(c, fmi2Error, "%s: not supported by this FMU (see its capability flags)", fn);
    st = fmi2Error;
    END()
}
EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                               const fmi2ValueReference z[], size_t nz,
                                               const fmi2Real dv[], fmi2Real dz[]) {
    (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz;
    return unsupported(c, "fmi2GetDirectionalDerivative");
}
EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                              const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    return unsupported(c, "fmi2SetRealInputDerivatives");
}
EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                               const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    return unsupported(c, "fmi2GetRealOutputDerivatives");
}

/* ------------------------------------------------------------------ FMI: FMU states */
static State *find_state(Inst *c, fmi2FMUstate s) {
    for (size_t i = 0; i < c->n_states; i++)
        if (c->states[i] == (State *)s) return c->states[i];
    return NULL;
}

static State *new_state(Inst *c, PyObject *obj) {
    if (c->n_states == c->cap_states) {
        size_t cap = c->cap_states ? 2 * c->cap_states : 8;
        State **grown = realloc(c->states, cap * sizeof(State *));
        if (grown == NULL) return NULL;
        c->states = grown;
        c->cap_states = cap;
    }
    State *s = malloc(sizeof(State));
    if (s == NULL) return NULL;
    s->magic = MAGIC;
    s->obj = obj;
    py.Py_IncRef(obj);
    c->states[c->n_states++] = s;
    return s;
}

/* Keep `payload` (a Python state object) as the FMU state *FMUstate: in place of `existing`'s
 * object when the host passed one of ours, else in a new state handle. */
static fmi2Status keep_state(Inst *c, const char *fn, State *existing, PyObject *payload,
                             fmi2FMUstate *FMUstate) {
    if (existing) {
        py.Py_IncRef(payload);
        py.Py_DecRef(existing->obj);
        existing->obj = payload;
        return fmi2OK;
    }
    State *s = new_state(c, payload);
    if (s == NULL) {
        logf_inst(c, fmi2Error, "%s: out of memory", fn);
        return fmi2Error;
    }
    *FMUstate = s;
    return fmi2OK;
}

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *FMUstate) {
    BEGIN("fmi2GetFMUstate")
    if (FMUstate == NULL) {
        logf_inst(c, fmi2Error, "fmi2GetFMUstate: FMUstate is NULL");
        st = fmi2Error;
        END()
    }
    State *existing = NULL;
    if (*FMUstate != NULL && (existing = find_state(c, *FMUstate)) == NULL) {
        logf_inst(c, fmi2Error, "fmi2GetFMUstate: *FMUstate is neither NULL nor a state of this instance");
        st = fmi2Error;
        END()
    }
    PyObject *payload, *result = py.PyObject_CallMethod(c->obj, "get_state", NULL);
    st = finish(c, "fmi2GetFMUstate", result, &payload);
    if (st <= fmi2Warning && payload != NULL
        && keep_state(c, "fmi2GetFMUstate", existing, payload, FMUstate) != fmi2OK)
        st = fmi2Error;
    if (result) py.Py_DecRef(result);
    END()
}

EXPORT fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate FMUstate) {
    BEGIN("fmi2SetFMUstate")
    State *s = find_state(c, FMUstate);
    if (s == NULL) {
        logf_inst(c, fmi2Error, "fmi2SetFMUstate: not a state of this instance (unknown or freed pointer)");
        st = fmi2Error;
        END()
    }
    PyObject *result = py.PyObject_CallMethod(c->obj, "set_state", "(O)", s->obj);
    st = finish(c, "fmi2SetFMUstate", result, NULL);
    if (result) py.Py_DecRef(result);
    END()
}

EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *FMUstate) {
    Inst *c = (Inst *)comp;
    if (c == NULL || !is_live(c)) return fmi2Error;
    if (FMUstate == NULL || *FMUstate == NULL) return fmi2OK; /* nothing to free */
    for (size_t i = 0; i < c->n_states; i++) {
        if (c->states[i] == (State *)*FMUstate) {
            if (py.Py_IsInitialized()) {
                PyGILState_STATE gil = py.PyGILState_Ensure();
                py.Py_DecRef(c->states[i]->obj);
                py.PyGILState_Release(gil);
            }
            c->states[i]->magic = 0;
            free(c->states[i]);
            c->states[i] = c->states[--c->n_states];
            *FMUstate = NULL;
            return fmi2OK;
        }
    }
    logf_inst(c, fmi2Error, "fmi2FreeFMUstate: not a state of this instance (unknown or freed pointer)");
    return fmi2Error;
}

static PyObject *serialized(Inst *c, const char *fn, fmi2FMUstate FMUstate, fmi2Status *st) {
    State *s = find_state(c, FMUstate);
    if (s == NULL) {
        logf_inst(c, fmi2Error, "%s: not a state of this instance (unknown or freed pointer)", fn);
        *st = fmi2Error;
        return NULL;
    }
    PyObject *payload, *result = py.PyObject_CallMethod(c->obj, "serialize", "(O)", s->obj);
    *st = finish(c, fn, result, &payload);
    if (*st <= fmi2Warning && payload != NULL && py.PyBytes_Size(payload) >= 0) {
        py.Py_IncRef(payload);
    } else {
        py.PyErr_Clear();
        payload = NULL;
        if (*st <= fmi2Warning) *st = fmi2Error;
    }
    if (result) py.Py_DecRef(result);
    return payload;
}

EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate FMUstate, size_t *size) {
    BEGIN("fmi2SerializedFMUstateSize")
    if (size == NULL) {
        logf_inst(c, fmi2Error, "fmi2SerializedFMUstateSize: size is NULL");
        st = fmi2Error;
        END()
    }
    PyObject *bytes = serialized(c, "fmi2SerializedFMUstateSize", FMUstate, &st);
    if (bytes) { *size = (size_t)py.PyBytes_Size(bytes); py.Py_DecRef(bytes); }
    END()
}

EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate FMUstate, fmi2Byte serializedState[],
                                        size_t size) {
    BEGIN("fmi2SerializeFMUstate")
    if (size > 0 && serializedState == NULL) {
        logf_inst(c, fmi2Error, "fmi2SerializeFMUstate: serializedState is NULL");
        st = fmi2Error;
        END()
    }
    PyObject *bytes = serialized(c, "fmi2SerializeFMUstate", FMUstate, &st);
    if (bytes) {
        size_t n = (size_t)py.PyBytes_Size(bytes);
        if (n != size) {
            logf_inst(c, fmi2Error, "fmi2SerializeFMUstate: size = %zu, the state needs %zu bytes", size, n);
            st = fmi2Error;
        } else {
            memcpy(serializedState, py.PyBytes_AsString(bytes), n);
        }
        py.Py_DecRef(bytes);
    }
    END()
}

EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte serializedState[], size_t size,
                                          fmi2FMUstate *FMUstate) {
    BEGIN("fmi2DeSerializeFMUstate")
    if (FMUstate == NULL || (size > 0 && serializedState == NULL) || size > (64u << 20)) {
        logf_inst(c, fmi2Error, "fmi2DeSerializeFMUstate: %s", FMUstate == NULL ? "FMUstate is NULL"
                  : size > (64u << 20) ? "size is not plausible" : "serializedState is NULL");
        st = fmi2Error;
        END()
    }
    State *existing = NULL;
    if (*FMUstate != NULL && (existing = find_state(c, *FMUstate)) == NULL) {
        logf_inst(c, fmi2Error, "fmi2DeSerializeFMUstate: *FMUstate is neither NULL nor a state of this instance");
        st = fmi2Error;
        END()
    }
    PyObject *bytes = py.PyBytes_FromStringAndSize(size ? serializedState : "", (ssize_t)size);
    PyObject *payload, *result = bytes ? py.PyObject_CallMethod(c->obj, "deserialize", "(O)", bytes) : NULL;
    if (bytes) py.Py_DecRef(bytes);
    st = finish(c, "fmi2DeSerializeFMUstate", result, &payload);
    if (st <= fmi2Warning && payload != NULL
        && keep_state(c, "fmi2DeSerializeFMUstate", existing, payload, FMUstate) != fmi2OK)
        st = fmi2Error;
    if (result) py.Py_DecRef(result);
    END()
}
