/*
 * lpvest status bridge: the FMI 2.0 co-simulation binary of an lpvest FMU.
 *
 * pythonfmu's export library (shipped next to this one in binaries/<platform>/
 * as INNER_LIBRARY) turns every Python exception into fmi2Fatal and has no way
 * for a Python slave to return fmi2Error or fmi2Warning. This thin layer loads
 * that library, forwards every FMI call to it, and returns as the call's status
 * the most severe of (a) the inner status and (b) the statuses the slave gave
 * its own log messages during that call. The lpvest slaves never raise: they
 * log bad input at status fmi2Error and leave their state unchanged, so a host
 * sees fmi2Error with a message naming the variable and can still free, reset
 * or restore the instance.
 *
 * Logging: this layer's own messages start with "[<model identifier>] " as the
 * slaves' and the native FMUs' do (the identifier is this library's file name).
 * The inner library only forwards messages when logging is on, so it
 * is always instantiated with logging on; this layer forwards every message of
 * status warning or worse to the host, and the others only when the host turned
 * logging on (for the categories it chose). Messages reach the host as a
 * format string without arguments, every '%' doubled.
 *
 * Time: fmi2GetRealStatus(fmi2LastSuccessfulTime) is the FMU's current time:
 * the start time after fmi2SetupExperiment, t + h after a step that returned
 * fmi2OK or fmi2Warning, unchanged after a refused step (pythonfmu's library
 * would report the refused step's t), and after fmi2SetFMUstate the restored
 * time, which the slave states in a log message of category "lpvest.time"
 * (consumed here, never shown to the host) as the 16 hexadecimal digits of its
 * IEEE 754 bits (strtod would read "1.25" as 1 in a host whose locale writes a
 * decimal comma). fmi2GetBooleanStatus(fmi2Terminated) is fmi2False: an lpvest
 * slave never asks to end the simulation; the statuses of fmi2GetStatus,
 * fmi2GetIntegerStatus and fmi2GetStringStatus are not available (fmi2Discard,
 * FMI 2.0, 4.2.3).
 *
 * Strings: pythonfmu turns a C string into a Python one, and a string that is not
 * UTF-8 (FMI 2.0's encoding) makes it crash the host (an instance name, a
 * resources folder) or fail with fmi2Fatal and a NULL log category (fmi2SetString);
 * a NULL string value became the text "None". This layer refuses them first, at
 * fmi2Error with a message, as the native FMUs do.
 *
 * Lifecycle: pythonfmu 0.7's fmi2FreeInstance destroys an instance's logger
 * before the instance, whose destructor then passes the messages still queued
 * on the Python side through that destroyed logger (a use-after-free: the host
 * crashes when the logger was on). The queue is drained at the end of every
 * FMI call except fmi2Instantiate and fmi2Reset, the two that run the slave's
 * constructor. So this layer drains it right after those two (a zero-length
 * fmi2GetReal, which calls no slave code but the getter of no variable) and
 * pythonfmu never frees an instance with queued messages, whatever its slave
 * logs while constructed. After the inner library returned fmi2Fatal (a Python
 * exception: it has then released the instance's Python objects already, and
 * freeing it would release them again), no call reaches the inner instance any
 * more: every call returns fmi2Fatal and fmi2FreeInstance frees only this
 * layer's part (the inner instance, a few hundred bytes, is left allocated).
 *
 * Instantiation: pythonfmu's library decodes only "%20" in the resource location
 * and crashes the host (a null Python callable) when it cannot import the slave
 * from it: a folder name with a non-ASCII letter or a '%', a location that is
 * NULL, resources without slavemodule.txt or its module. So this layer checks
 * first: a co-simulation instance, a file URI (file:///path, file:/path,
 * file://localhost/path; every %XX decoded) whose folder holds slavemodule.txt,
 * the module it names, and RESOURCE_GUID_FILE holding the GUID the host gave;
 * else it logs why at fmi2Error and returns NULL. The inner library gets the
 * decoded folder as "file://" + path (Windows: "file:///" + path, as it strips
 * eight characters there).
 *
 * FMU states: the inner library copies exactly the buffer size the host gives
 * out of the state (reading past its end for a larger buffer: heap bytes, or a
 * crash), leaves *state set after fmi2FreeFMUstate, and takes NULL states as
 * Python objects. This layer serializes exactly fmi2SerializedFMUstateSize
 * bytes (zeros after them; fmi2Error for a smaller buffer), sets *state to NULL
 * after a free (a NULL state is freed at once), refuses NULL arguments at
 * fmi2Error, and gives fmi2GetFMUstate on an earlier state (*state != NULL)
 * a new one after freeing the earlier (FMI 2.0 allows either).
 *
 * Platforms: Linux (dlopen; compiled by the build with the C compiler) and
 * Windows (LoadLibrary; cross-compiled by the build with zig). The inner library
 * is the file INNER_LIBRARY in the folder of this library's own file.
 *
 * No Python API is used here; the Python interpreter is the host's (or loaded
 * with LD_PRELOAD for a C host), exactly as for pythonfmu's own library.
 */
#ifndef _WIN32
#define _GNU_SOURCE
#endif
#include <ctype.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* the checks and words both backends share (the native runtime's header) */
#include "native/runtime/lpv_host_words.h"

#ifdef _WIN32
#include <windows.h>
#define EXPORT __declspec(dllexport)
static SRWLOCK load_lock = SRWLOCK_INIT;
#define LOAD_LOCK() AcquireSRWLockExclusive(&load_lock)
#define LOAD_UNLOCK() ReleaseSRWLockExclusive(&load_lock)
#ifndef INNER_LIBRARY
#define INNER_LIBRARY "lpvest-pythonfmu-export.dll"
#endif
#else
#include <dlfcn.h>
#include <pthread.h>
#define EXPORT __attribute__((visibility("default")))
static pthread_mutex_t load_lock = PTHREAD_MUTEX_INITIALIZER;
#define LOAD_LOCK() pthread_mutex_lock(&load_lock)
#define LOAD_UNLOCK() pthread_mutex_unlock(&load_lock)
#ifndef INNER_LIBRARY
#define INNER_LIBRARY "lpvest-pythonfmu-export.so"
#endif
#endif

/* --- the FMI 2.0 types (fmi2TypesPlatform.h, fmi2FunctionTypes.h) --- */
typedef void* fmi2Component;
typedef void* fmi2ComponentEnvironment;
typedef void* fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char* fmi2String;
typedef char fmi2Byte;
#define fmi2True 1
#define fmi2False 0

typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;

typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
typedef void* (*fmi2CallbackAllocateMemory)(size_t, size_t);
typedef void (*fmi2CallbackFreeMemory)(void*);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment, fmi2Status);

typedef struct {
    fmi2CallbackLogger logger;
    fmi2CallbackAllocateMemory allocateMemory;
    fmi2CallbackFreeMemory freeMemory;
    fmi2StepFinished stepFinished;
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

/* --- the inner library's functions --- */
typedef struct {
    fmi2Component (*Instantiate)(fmi2String, fmi2Type, fmi2String, fmi2String, const fmi2CallbackFunctions*,
                                 fmi2Boolean, fmi2Boolean);
    void (*FreeInstance)(fmi2Component);
    fmi2Status (*SetupExperiment)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real);
    fmi2Status (*EnterInitializationMode)(fmi2Component);
    fmi2Status (*ExitInitializationMode)(fmi2Component);
    fmi2Status (*Terminate)(fmi2Component);
    fmi2Status (*Reset)(fmi2Component);
    fmi2Status (*GetReal)(fmi2Component, const fmi2ValueReference*, size_t, fmi2Real*);
    fmi2Status (*GetInteger)(fmi2Component, const fmi2ValueReference*, size_t, fmi2Integer*);
    fmi2Status (*GetBoolean)(fmi2Component, const fmi2ValueReference*, size_t, fmi2Boolean*);
    fmi2Status (*GetString)(fmi2Component, const fmi2ValueReference*, size_t, fmi2String*);
    fmi2Status (*SetReal)(fmi2Component, const fmi2ValueReference*, size_t, const fmi2Real*);
    fmi2Status (*SetInteger)(fmi2Component, const fmi2ValueReference*, size_t, const fmi2Integer*);
    fmi2Status (*SetBoolean)(fmi2Component, const fmi2ValueReference*, size_t, const fmi2Boolean*);
    fmi2Status (*SetString)(fmi2Component, const fmi2ValueReference*, size_t, const fmi2String*);
    fmi2Status (*GetFMUstate)(fmi2Component, fmi2FMUstate*);
    fmi2Status (*SetFMUstate)(fmi2Component, fmi2FMUstate);
    fmi2Status (*FreeFMUstate)(fmi2Component, fmi2FMUstate*);
    fmi2Status (*SerializedFMUstateSize)(fmi2Component, fmi2FMUstate, size_t*);
    fmi2Status (*SerializeFMUstate)(fmi2Component, fmi2FMUstate, fmi2Byte*, size_t);
    fmi2Status (*DeSerializeFMUstate)(fmi2Component, const fmi2Byte*, size_t, fmi2FMUstate*);
    fmi2Status (*DoStep)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);
    fmi2Status (*GetRealStatus)(fmi2Component, fmi2StatusKind, fmi2Real*);
} Inner;

static Inner inner;
static int inner_loaded = 0;
#ifndef _WIN32
static void (*inner_finalize)(void) = NULL;
#endif

/* pythonfmu 0.7's library has a use-after-free at process exit: the static
 * shared_ptr holding its interpreter state is destroyed by an exit handler, and
 * then its destructor function (finalizePythonInterpreter) assigns to the
 * destroyed pointer, releasing the state a second time (heap corruption, an
 * abort at exit in about one run in five here). Calling finalizePythonInterpreter
 * from an exit handler registered after the library is loaded (exit handlers
 * run in reverse order) releases the state once, while the pointer is alive;
 * both later calls then see an empty pointer. */
#ifndef _WIN32
static void finalize_inner(void) {
    if (inner_finalize) inner_finalize();
}
#endif

typedef struct {
    fmi2Component inner;
    int filter;                   /* 1: only the categories listed are forwarded (fmi2SetDebugLogging) */
    fmi2CallbackFunctions host;   /* the host's callbacks (copied) */
    fmi2CallbackFunctions mine;   /* given to the inner library; lives as long as the instance */
    char* name;
    fmi2Boolean logging_on;
    size_t n_categories;
    char** categories;
    fmi2Status worst;             /* most severe status logged during the current call */
    fmi2Real time;                /* the FMU's current time (fmi2LastSuccessfulTime) */
    int broken;                   /* the inner library returned fmi2Fatal: never call it again */
} Bridge;

/* the file in resources/ that holds the FMU's GUID (written by lpvest's build; see the top of this file) */
#define RESOURCE_GUID_FILE "lpvest_guid.txt"

/* the category of the slave's messages that state its time (see the top of this file) */
#define TIME_CATEGORY "lpvest.time"

static char* safe_format(const char* message);

/* the model identifier: this library's file name without its folder and extension (set once, under
   LOAD_LOCK, by fmi2Instantiate before its first message); "" where it cannot be found */
static char model_identifier[128];

static void find_model_identifier(void) {
    if (model_identifier[0]) return;
    char file[1024] = {0};
#ifdef _WIN32
    HMODULE self = NULL;
    wchar_t path[1024];
    if (!GetModuleHandleExW(GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS | GET_MODULE_HANDLE_EX_FLAG_UNCHANGED_REFCOUNT,
                            (LPCWSTR)(void*)&find_model_identifier, &self))
        return;
    DWORD n = GetModuleFileNameW(self, path, (DWORD)(sizeof path / sizeof path[0]));
    if (n == 0 || n >= sizeof path / sizeof path[0]) return;
    for (DWORD i = 0; i <= n && i < sizeof file - 1; i++) file[i] = path[i] < 128 ? (char)path[i] : '_';
#else
    Dl_info info;
    if (!dladdr((void*)&find_model_identifier, &info) || !info.dli_fname) return;
    snprintf(file, sizeof file, "%s", info.dli_fname);
#endif
    const char* base = file;
    for (const char* q = file; *q; q++)
        if (*q == '/' || *q == '\\') base = q + 1;
    size_t len = strcspn(base, ".");
    if (len >= sizeof model_identifier) len = sizeof model_identifier - 1;
    memcpy(model_identifier, base, len);
    model_identifier[len] = '\0';
}

static void report(fmi2CallbackLogger logger, fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   const char* text) {
    if (!logger) return;
    char prefixed[1200];
    if (model_identifier[0]) {
        snprintf(prefixed, sizeof prefixed, "[%s] %s", model_identifier, text);
        text = prefixed;
    }
    char* fmt = safe_format(text);
    const char* category = status == fmi2Fatal   ? "logStatusFatal"
                           : status == fmi2Error   ? "logStatusError"
                           : status == fmi2Discard ? "logStatusDiscard"
                                                   : "logStatusWarning";
    logger(env, name ? name : "", status, category, fmt ? fmt : "lpvest status bridge: out of memory");
    free(fmt);
}

static char* copy_string(const char* text) {
    size_t n = strlen(text) + 1;
    char* out = (char*)malloc(n);
    if (out) memcpy(out, text, n);
    return out;
}

#define LOAD_ALL(LOAD)                                                                                          \
    LOAD(Instantiate) LOAD(FreeInstance) LOAD(SetupExperiment) LOAD(EnterInitializationMode)                    \
    LOAD(ExitInitializationMode) LOAD(Terminate) LOAD(Reset) LOAD(GetReal) LOAD(GetInteger) LOAD(GetBoolean)    \
    LOAD(GetString) LOAD(SetReal) LOAD(SetInteger) LOAD(SetBoolean) LOAD(SetString) LOAD(GetFMUstate)           \
    LOAD(SetFMUstate) LOAD(FreeFMUstate) LOAD(SerializedFMUstateSize) LOAD(SerializeFMUstate)                   \
    LOAD(DeSerializeFMUstate) LOAD(DoStep) LOAD(GetRealStatus)

#ifdef _WIN32
static int load_inner(const fmi2CallbackFunctions* host, fmi2String name) {
    if (inner_loaded) return 1;
    fmi2CallbackLogger logger = host ? host->logger : NULL;
    fmi2ComponentEnvironment env = host ? host->componentEnvironment : NULL;
    HMODULE self = NULL;
    wchar_t path[32768];
    if (!GetModuleHandleExW(GET_MODULE_HANDLE_EX_FLAG_FROM_ADDRESS | GET_MODULE_HANDLE_EX_FLAG_UNCHANGED_REFCOUNT,
                            (LPCWSTR)(void*)&load_inner, &self)) {
        report(logger, env, name, fmi2Fatal, "lpvest status bridge: cannot find its own file (GetModuleHandleExW)");
        return 0;
    }
    const DWORD cap = (DWORD)(sizeof path / sizeof path[0]);
    DWORD n = GetModuleFileNameW(self, path, cap);
    if (n == 0 || n >= cap) {
        report(logger, env, name, fmi2Fatal, "lpvest status bridge: cannot find its own file (GetModuleFileNameW)");
        return 0;
    }
    DWORD dir_len = n;
    while (dir_len > 0 && path[dir_len - 1] != L'\\' && path[dir_len - 1] != L'/') dir_len--;
    const char* file = INNER_LIBRARY;
    size_t file_len = strlen(file);
    if (dir_len + file_len + 1 > cap) {
        report(logger, env, name, fmi2Fatal, "lpvest status bridge: the path of its folder is too long");
        return 0;
    }
    for (size_t i = 0; i <= file_len; i++) path[dir_len + i] = (wchar_t)(unsigned char)file[i];
    /* the inner library's own dependencies (python3.dll, the C++ runtime) are looked up as when a host
       loads it directly, its folder first */
    HMODULE h = LoadLibraryExW(path, NULL, LOAD_WITH_ALTERED_SEARCH_PATH);
    if (!h) {
        char msg[512];
        snprintf(msg, sizeof msg,
                 "lpvest status bridge: cannot load %s next to it (Windows error %lu; python3.dll must be found: "
                 "run the FMU in a Python host or put Python's folder on PATH)",
                 INNER_LIBRARY, (unsigned long)GetLastError());
        report(logger, env, name, fmi2Fatal, msg);
        return 0;
    }
#define LOAD(field)                                                                                  \
    inner.field = (__typeof__(inner.field))(void (*)(void))GetProcAddress(h, "fmi2" #field);        \
    if (!inner.field) {                                                                              \
        report(logger, env, name, fmi2Fatal, "lpvest status bridge: the inner library lacks fmi2" #field); \
        return 0;                                                                                    \
    }
    LOAD_ALL(LOAD)
#undef LOAD
    /* pythonfmu's DLL finalizes its interpreter state in its own DllMain (no exit-order problem there) */
    inner_loaded = 1; /* never unloaded: pythonfmu keeps its interpreter thread alive anyway */
    return 1;
}
#else
/* In a C host (libpython preloaded, no interpreter running yet) pythonfmu's library starts the
 * interpreter on a thread of its own and finalizes it at exit, after the exit handlers of the
 * extension modules loaded since have run (scipy's among them): Py_Finalize then crashes the
 * exiting host. So the interpreter is started here, once, as a Python host's is, and kept
 * until the process ends (pythonfmu then neither starts nor finalizes one). Without libpython
 * in the process nothing is started, and loading the inner library fails as it says below. */
static void start_python(void) {
    int (*is_initialized)(void) = (int (*)(void))dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    void (*initialize)(int) = (void (*)(int))dlsym(RTLD_DEFAULT, "Py_InitializeEx");
    void* (*release_gil)(void) = (void* (*)(void))dlsym(RTLD_DEFAULT, "PyEval_SaveThread");
    if (!is_initialized || !initialize || !release_gil || is_initialized()) return;
    initialize(0); /* 0: no signal handlers, the host's stay */
    release_gil(); /* pythonfmu takes the GIL in every call (PyGILState_Ensure), from any thread */
}

static int load_inner(const fmi2CallbackFunctions* host, fmi2String name) {
    if (inner_loaded) return 1;
    fmi2CallbackLogger logger = host ? host->logger : NULL;
    fmi2ComponentEnvironment env = host ? host->componentEnvironment : NULL;
    Dl_info info;
    if (!dladdr((void*)&load_inner, &info) || !info.dli_fname) {
        report(logger, env, name, fmi2Fatal, "lpvest status bridge: cannot find its own file (dladdr failed)");
        return 0;
    }
    start_python();
    const char* slash = strrchr(info.dli_fname, '/');
    size_t dir_len = slash ? (size_t)(slash - info.dli_fname + 1) : 0;
    size_t len = dir_len + strlen(INNER_LIBRARY) + 1;
    char* path = (char*)malloc(len);
    if (!path) return 0;
    memcpy(path, info.dli_fname, dir_len);
    strcpy(path + dir_len, INNER_LIBRARY);
    void* h = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!h) {
        char msg[2048];
        snprintf(msg, sizeof msg,
                 "lpvest status bridge: cannot load %s: %s (a C host must load libpython first, "
                 "e.g. LD_PRELOAD=libpython3.x.so)",
                 path, dlerror());
        report(logger, env, name, fmi2Fatal, msg);
        free(path);
        return 0;
    }
    free(path);
#define LOAD(field)                                                                                  \
    inner.field = (__typeof__(inner.field))dlsym(h, "fmi2" #field);                                 \
    if (!inner.field) {                                                                              \
        report(logger, env, name, fmi2Fatal, "lpvest status bridge: the inner library lacks fmi2" #field); \
        return 0;                                                                                    \
    }
    LOAD_ALL(LOAD)
#undef LOAD
    /* this library stays loaded from now on, as the inner one does (its handle is never closed): a
       host's dlclose would otherwise run the exit handler below, and a C host whose interpreter the
       inner library started would see it finalized (numpy cannot be imported again after that) */
    if (!dlopen(info.dli_fname, RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE)) {
        report(logger, env, name, fmi2Fatal, "lpvest status bridge: cannot keep itself loaded (dlopen)");
        return 0;
    }
    inner_finalize = (void (*)(void))dlsym(h, "finalizePythonInterpreter");
    if (inner_finalize) atexit(finalize_inner);
    inner_loaded = 1;  /* never unloaded: pythonfmu keeps its interpreter thread alive anyway */
    return 1;
}
#endif

/* The text is handed on as the format string with no arguments (hosts that
 * bind the logger without varargs, e.g. through ctypes, print the format
 * itself): a message that is already a safe format (every '%' doubled, as the
 * lpvest slaves write them) is passed unchanged, any other is escaped. No
 * variadic argument is ever read. */
static char* safe_format(const char* message) {
    if (!message) message = "";
    size_t n = strlen(message), extra = 0;
    int safe = 1;
    for (size_t i = 0; i < n; i++) {
        if (message[i] == '%') extra++;
    }
    for (size_t i = 0; i < n; i++) {
        if (message[i] == '%') {
            if (i + 1 < n && message[i + 1] == '%') {
                i++;
            } else {
                safe = 0;
            }
        }
    }
    char* out = (char*)malloc(n + (safe ? 0 : extra) + 1);
    if (!out) return NULL;
    size_t j = 0;
    for (size_t i = 0; i < n; i++) {
        out[j++] = message[i];
        if (!safe && message[i] == '%') out[j++] = '%';
    }
    out[j] = '\0';
    return out;
}

/* the log categories of the model description (pythonfmu's), as the native FMUs know them */
static const char* const CATEGORIES[] = {"logStatusWarning", "logStatusDiscard", "logStatusError", "logStatusFatal",
                                         "logAll"};

static int category_enabled(const Bridge* b, fmi2String category) {
    if (!b->filter) return 1;
    if (!category) return 0;
    for (size_t i = 0; i < b->n_categories; i++)
        if (strcmp(b->categories[i], category) == 0) return 1;
    return 0;
}

static void bridge_logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                          fmi2String message, ...) {
    Bridge* b = (Bridge*)env;
    if (!b) return;
    if (category && strcmp(category, TIME_CATEGORY) == 0) {
        /* 16 hexadecimal digits, the bits of the time (see the top of this file) */
        char* end = NULL;
        unsigned long long bits = message ? strtoull(message, &end, 16) : 0;
        if (message && end == message + 16 && *end == '\0') memcpy(&b->time, &bits, sizeof b->time);
        return;
    }
    if (status > b->worst && status <= fmi2Error) b->worst = status;
    int forward = status >= fmi2Warning || (b->logging_on && category_enabled(b, category));
    if (!forward || !b->host.logger) return;
    char* text = safe_format(message);
    b->host.logger(b->host.componentEnvironment, name, status, category, text ? text : "(out of memory)");
    free(text);
}

static fmi2Status combine(Bridge* b, fmi2Status inner_status) {
    if (inner_status == fmi2Fatal) b->broken = 1;
    if (inner_status == fmi2Fatal || inner_status == fmi2Pending) return inner_status;
    return b->worst > inner_status ? b->worst : inner_status;
}

/* every call after the inner library returned fmi2Fatal (see the top of this file) */
static fmi2Status refuse_broken(Bridge* b, const char* what) {
    char msg[256];
    snprintf(msg, sizeof msg,
             "%s: an earlier call failed with fmi2Fatal (a Python exception in the slave); the instance can "
             "only be freed",
             what);
    report(b->host.logger, b->host.componentEnvironment, b->name, fmi2Fatal, msg);
    return fmi2Fatal;
}

/* An argument the inner library would crash on (a NULL state, pointer, buffer or array):
 * fmi2Error with "what: why", the call not forwarded. */
static fmi2Status refuse_argument(Bridge* b, const char* what, const char* why) {
    char msg[256];
    snprintf(msg, sizeof msg, "%s: %s", what, why);
    report(b->host.logger, b->host.componentEnvironment, b->name, fmi2Error, msg);
    return fmi2Error;
}

/* the words for a NULL argument of an FMU-state call, and (the native FMUs' words) of a getter
 * or setter given nvr > 0 */
#define NULL_ARGUMENT LPV_NULL_ARGUMENT
/* how every state lpvest/fmi/_state.py's encode_state writes begins (json.dumps of a dict whose
   first key is its format): other bytes are refused when deserialized, as the native FMUs refuse
   bytes without their header (tests/test_status_bridge.py checks this against encode_state) */
#define STATE_PREFIX "{\"format\": \"lpvest-fmu-state-2\""
#define NULL_ARRAY "a null array"

#define BRIDGE(c) ((Bridge*)(c))
/* the call forwarded to the inner library, its status combined with what the slave logged,
 * when ok holds; else refuse_argument with why */
#define CHECKED(c, what, ok, why, call)                  \
    do {                                                 \
        Bridge* b_ = BRIDGE(c);                          \
        if (!b_) return fmi2Error;                       \
        if (b_->broken) return refuse_broken(b_, what);  \
        if (!(ok)) return refuse_argument(b_, what, why); \
        b_->worst = fmi2OK;                              \
        fmi2Status s_ = call;                            \
        return combine(b_, s_);                          \
    } while (0)
/* a getter or setter (pythonfmu would read through a NULL array) */
#define FORWARD_ARRAYS(c, what, call) CHECKED(c, what, !nvr || (vr && value), NULL_ARRAY, call)
/* a call with nothing to check but the instance */
#define FORWARD(c, what, call) CHECKED(c, what, 1, "", call)

/* After the slave was constructed (fmi2Instantiate, fmi2Reset): have pythonfmu hand on what the
 * constructor logged, which it otherwise keeps queued until the next call, and which its
 * fmi2FreeInstance would pass through a destroyed logger (see the top of this file). A
 * zero-length fmi2GetReal runs no getter; pythonfmu drains its queue at its end. */
static fmi2Status drain(Bridge* b) {
    return inner.GetReal(b->inner, NULL, 0, NULL);
}

/* The folder a resource location names, %XX decoded, without a trailing '/' (malloc'd), or NULL:
 * not a file URI, or one that decodes to a NUL. */
static char* resource_folder(const char* uri) {
    const char* p;
    if (strncmp(uri, "file://localhost/", 17) == 0) {
        p = uri + 16;
    } else if (strncmp(uri, "file:///", 8) == 0) {
        p = uri + 7;
    } else if (strncmp(uri, "file:/", 6) == 0 && uri[6] != '/') {
        p = uri + 5;
    } else {
        return NULL;
    }
#ifdef _WIN32
    if (p[0] == '/' && isalpha((unsigned char)p[1]) && p[2] == ':') p++; /* /C:/x -> C:/x */
#endif
    size_t n = strlen(p), j = 0;
    char* out = (char*)malloc(n + 1);
    if (!out) return NULL;
    for (size_t i = 0; i < n; i++) {
        if (p[i] == '%' && isxdigit((unsigned char)p[i + 1]) && isxdigit((unsigned char)p[i + 2])) {
            char hex[3] = {p[i + 1], p[i + 2], '\0'};
            out[j] = (char)strtol(hex, NULL, 16);
            if (out[j] == '\0') {
                free(out);
                return NULL;
            }
            j++;
            i += 2;
        } else {
            out[j++] = p[i];
        }
    }
    while (j > 1 && out[j - 1] == '/') j--;
    out[j] = '\0';
    return out;
}

/* The first line of folder/name (at most cap - 1 bytes, surrounding white space removed) into line;
 * 0 if the file cannot be read or the line is empty. The folder is UTF-8 (Windows: opened as such). */
static int read_first_line(const char* folder, const char* name, char* line, size_t cap) {
    size_t len = strlen(folder) + 1 + strlen(name) + 1;
    char* path = (char*)malloc(len);
    if (!path) return 0;
    snprintf(path, len, "%s/%s", folder, name);
#ifdef _WIN32
    FILE* f = NULL;
    int wn = MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, path, -1, NULL, 0);
    wchar_t* wpath = wn > 0 ? (wchar_t*)malloc((size_t)wn * sizeof(wchar_t)) : NULL;
    if (wpath && MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, path, -1, wpath, wn) == wn)
        f = _wfopen(wpath, L"rb");
    free(wpath);
#else
    FILE* f = fopen(path, "rb");
#endif
    free(path);
    if (!f) return 0;
    size_t got = fread(line, 1, cap - 1, f);
    fclose(f);
    line[got] = '\0';
    line[strcspn(line, "\r\n")] = '\0';
    size_t start = 0, end = strlen(line);
    while (start < end && isspace((unsigned char)line[start])) start++;
    while (end > start && isspace((unsigned char)line[end - 1])) end--;
    memmove(line, line + start, end - start);
    line[end - start] = '\0';
    return line[0] != '\0';
}

/* Why an instance cannot be made of this type, GUID and resource location (a message in msg),
 * or NULL with the folder to hand on in *folder (malloc'd). */
static const char* refuse_instantiate(fmi2Type type, fmi2String guid, fmi2String location, char** folder, char* msg,
                                      size_t cap) {
    *folder = NULL;
    if (type != fmi2CoSimulation) return "fmi2Instantiate: this FMU supports co-simulation only";
    if (!location) return "fmi2Instantiate: " LPV_NO_RESOURCES;
    char* dir = resource_folder(location);
    if (!dir) {
        snprintf(msg, cap, "fmi2Instantiate: resource location %.300s is not a file URI (file:///path)", location);
        return msg;
    }
    char line[256], module[256];
    if (!read_first_line(dir, "slavemodule.txt", module, sizeof module) || strlen(module) + 4 >= sizeof module) {
        snprintf(msg, cap, "fmi2Instantiate: cannot read %.300s/slavemodule.txt: is the FMU extracted whole?", dir);
        goto refused;
    }
    strcat(module, ".py");
    if (!read_first_line(dir, module, line, sizeof line)) {
        snprintf(msg, cap, "fmi2Instantiate: cannot read %.300s/%.200s: is the FMU extracted whole?", dir, module);
        goto refused;
    }
    if (!read_first_line(dir, RESOURCE_GUID_FILE, line, sizeof line)) {
        snprintf(msg, cap, "fmi2Instantiate: cannot read %.300s/" RESOURCE_GUID_FILE ": is the FMU extracted whole?",
                 dir);
        goto refused;
    }
    if (guid && strcmp(guid, line) != 0) {
        snprintf(msg, cap, LPV_GUID_MISMATCH, guid, line);
        goto refused;
    }
    if (!lpv_is_utf8(dir)) { /* pythonfmu would crash the host: it makes a Python string of it */
        snprintf(msg, cap, "fmi2Instantiate: the path of the resources folder is not UTF-8 text, which pythonfmu "
                 "cannot load: extract the FMU into a folder whose path is");
        goto refused;
    }
    if (strstr(dir, "%20")) { /* the inner library would read it as a space */
        snprintf(msg, cap, "fmi2Instantiate: the resources folder %.300s has '%%20' in its name, which pythonfmu "
                 "reads as a space: extract the FMU elsewhere", dir);
        goto refused;
    }
    *folder = dir;
    return NULL;
refused:
    free(dir);
    return msg;
}

EXPORT const char* fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char* fmi2GetVersion(void) { return "2.0"; }

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                     fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions,
                                     fmi2Boolean visible, fmi2Boolean loggingOn) {
    LOAD_LOCK();
    find_model_identifier();
    LOAD_UNLOCK();
    char msg[1024], *folder = NULL;
    const char* why = !instanceName           ? "fmi2Instantiate: no instance name (NULL)"
                      : !lpv_is_utf8(instanceName) ? "fmi2Instantiate: the instance name is not UTF-8 text"
                      : !lpv_has_text(instanceName) ? "fmi2Instantiate: " LPV_BLANK_NAME
                      : refuse_instantiate(fmuType, fmuGUID, fmuResourceLocation, &folder, msg, sizeof msg);
    if (why) {
        report(functions ? functions->logger : NULL, functions ? functions->componentEnvironment : NULL,
               instanceName && lpv_is_utf8(instanceName) ? instanceName : "", fmi2Error, why);
        return NULL;
    }
#ifdef _WIN32
    const char* scheme = "file:///";
#else
    const char* scheme = "file://";
#endif
    size_t uri_len = strlen(scheme) + strlen(folder) + 1;
    char* uri = (char*)malloc(uri_len);
    if (uri) snprintf(uri, uri_len, "%s%s", scheme, folder);
    free(folder);
    if (!uri) return NULL;
    /* the first instantiations may come from several threads at once (a host that creates its
       instances in parallel): one of them loads the inner library and starts the interpreter, the
       others wait for it (two Py_InitializeEx at once crash the host) */
    LOAD_LOCK();
    int loaded = load_inner(functions, instanceName);
    LOAD_UNLOCK();
    if (!loaded) {
        free(uri);
        return NULL;
    }
    Bridge* b = (Bridge*)calloc(1, sizeof(Bridge));
    if (!b) {
        free(uri);
        return NULL;
    }
    if (functions) b->host = *functions;
    b->mine.logger = bridge_logger;
    b->mine.allocateMemory = b->host.allocateMemory ? b->host.allocateMemory : calloc;
    b->mine.freeMemory = b->host.freeMemory ? b->host.freeMemory : free;
    b->mine.stepFinished = NULL;
    b->mine.componentEnvironment = b;
    b->logging_on = loggingOn;
    b->name = copy_string(instanceName ? instanceName : "");
    if (!b->name) {
        free(uri);
        free(b);
        return NULL;
    }
    b->inner = inner.Instantiate(instanceName, fmuType, fmuGUID, uri, &b->mine, visible, fmi2True);
    free(uri);
    if (!b->inner) {
        free(b->name);
        free(b);
        return NULL;
    }
    if (drain(b) == fmi2Fatal) { /* the slave raised: nothing usable was made (pythonfmu logged why) */
        free(b->name);
        free(b);
        return NULL;
    }
    return b;
}

static void free_categories(Bridge* b) {
    for (size_t i = 0; i < b->n_categories; i++) free(b->categories[i]);
    free(b->categories);
    b->categories = NULL;
    b->n_categories = 0;
}

EXPORT void fmi2FreeInstance(fmi2Component c) {
    Bridge* b = BRIDGE(c);
    if (!b) return;
    if (!b->broken) inner.FreeInstance(b->inner); /* else left allocated: see the top of this file */
    free_categories(b);
    free(b->name);
    free(b);
}

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                                      const fmi2String categories[]) {
    Bridge* b = BRIDGE(c);
    if (!b) return fmi2Error;
    free_categories(b);
    b->logging_on = loggingOn;
    b->filter = nCategories > 0; /* none: every category; else only the known ones listed */
    if (nCategories == 0) return fmi2OK;
    b->categories = (char**)calloc(nCategories, sizeof(char*));
    if (!b->categories) return fmi2Error;
    fmi2Status status = fmi2OK;
    for (size_t i = 0; i < nCategories; i++) {
        const char* name = categories ? categories[i] : NULL;
        int known = 0;
        for (size_t k = 0; name && k < sizeof CATEGORIES / sizeof CATEGORIES[0]; k++) known |= !strcmp(name, CATEGORIES[k]);
        if (!known) { /* the native FMUs' words */
            char msg[300];
            snprintf(msg, sizeof msg, "fmi2SetDebugLogging: unknown log category %.200s",
                     !name ? "(null)" : lpv_is_utf8(name) ? name : "(not UTF-8 text)");
            report(b->host.logger, b->host.componentEnvironment, b->name, fmi2Warning, msg);
            status = fmi2Warning;
            continue;
        }
        b->categories[b->n_categories] = copy_string(name);
        if (!b->categories[b->n_categories]) {
            free_categories(b);
            return fmi2Error;
        }
        b->n_categories++;
    }
    return status;
}

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                                      fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Bridge* b = BRIDGE(c);
    if (!b) return fmi2Error;
    if (b->broken) return refuse_broken(b, "fmi2SetupExperiment");
    b->worst = fmi2OK;
    fmi2Status s = inner.SetupExperiment(b->inner, toleranceDefined, tolerance, startTime, stopTimeDefined, stopTime);
    s = combine(b, s); /* after the call: the messages it logged set b->worst */
    if (s <= fmi2Warning) b->time = startTime;
    return s;
}
EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    FORWARD(c, "fmi2EnterInitializationMode", inner.EnterInitializationMode(b_->inner));
}
EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c) { FORWARD(c, "fmi2ExitInitializationMode", inner.ExitInitializationMode(b_->inner)); }
EXPORT fmi2Status fmi2Terminate(fmi2Component c) { FORWARD(c, "fmi2Terminate", inner.Terminate(b_->inner)); }
EXPORT fmi2Status fmi2Reset(fmi2Component c) {
    Bridge* b = BRIDGE(c);
    if (!b) return fmi2Error;
    if (b->broken) return refuse_broken(b, "fmi2Reset");
    b->worst = fmi2OK;
    b->time = 0.0;
    fmi2Status s = inner.Reset(b->inner); /* runs the slave's constructor again */
    if (s != fmi2Fatal) {
        fmi2Status d = drain(b);
        if (d == fmi2Fatal) s = d;
    }
    return combine(b, s);
}

EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    FORWARD_ARRAYS(c, "fmi2GetReal", inner.GetReal(b_->inner, vr, nvr, value));
}
EXPORT fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    FORWARD_ARRAYS(c, "fmi2GetInteger", inner.GetInteger(b_->inner, vr, nvr, value));
}
EXPORT fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    FORWARD_ARRAYS(c, "fmi2GetBoolean", inner.GetBoolean(b_->inner, vr, nvr, value));
}
EXPORT fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    FORWARD_ARRAYS(c, "fmi2GetString", inner.GetString(b_->inner, vr, nvr, value));
}
EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    FORWARD_ARRAYS(c, "fmi2SetReal", inner.SetReal(b_->inner, vr, nvr, value));
}
EXPORT fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                 const fmi2Integer value[]) {
    FORWARD_ARRAYS(c, "fmi2SetInteger", inner.SetInteger(b_->inner, vr, nvr, value));
}
EXPORT fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                 const fmi2Boolean value[]) {
    FORWARD_ARRAYS(c, "fmi2SetBoolean", inner.SetBoolean(b_->inner, vr, nvr, value));
}
/* Why pythonfmu cannot take these string values (NULL, or not UTF-8: see the top of this file), in
 * the native FMUs' words, into msg; NULL if it can. */
static const char* refuse_strings(const fmi2ValueReference vr[], size_t nvr, const fmi2String value[], char* msg,
                                  size_t cap) {
    for (size_t i = 0; vr && value && i < nvr; i++) {
        if (value[i] && lpv_is_utf8(value[i])) continue;
        snprintf(msg, cap, "value reference %u: the value is %s; no value set", vr[i],
                 value[i] ? "not UTF-8 text" : "NULL");
        return msg;
    }
    return NULL;
}

EXPORT fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                const fmi2String value[]) {
    char msg[160];
    const char* why = refuse_strings(vr, nvr, value, msg, sizeof msg);
    CHECKED(c, "fmi2SetString", (!nvr || (vr && value)) && !why, why ? why : NULL_ARRAY,
            inner.SetString(b_->inner, vr, nvr, value));
}

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* state) {
    Bridge* b = BRIDGE(c);
    if (!b) return fmi2Error;
    if (b->broken) return refuse_broken(b, "fmi2GetFMUstate");
    if (!state) return refuse_argument(b, "fmi2GetFMUstate", NULL_ARGUMENT);
    b->worst = fmi2OK;
    if (*state) { /* an earlier state to update: freed, and a new one made (see the top of this file) */
        fmi2Status f = combine(b, inner.FreeFMUstate(b->inner, state));
        if (f > fmi2Warning) return f;
        *state = NULL;
    }
    return combine(b, inner.GetFMUstate(b->inner, state));
}
EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    CHECKED(c, "fmi2SetFMUstate", state, NULL_ARGUMENT, inner.SetFMUstate(b_->inner, state));
}
EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* state) {
    Bridge* b = BRIDGE(c);
    if (!b) return fmi2Error;
    if (!state || !*state) return fmi2OK; /* nothing to free (FMI 2.0) */
    if (b->broken) return refuse_broken(b, "fmi2FreeFMUstate");
    b->worst = fmi2OK;
    fmi2Status s = combine(b, inner.FreeFMUstate(b->inner, state));
    if (s <= fmi2Warning) *state = NULL;
    return s;
}
EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t* size) {
    CHECKED(c, "fmi2SerializedFMUstateSize", state && size, NULL_ARGUMENT,
            inner.SerializedFMUstateSize(b_->inner, state, size));
}
EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    Bridge* b = BRIDGE(c);
    if (!b) return fmi2Error;
    if (b->broken) return refuse_broken(b, "fmi2SerializeFMUstate");
    if (!state || !bytes) return refuse_argument(b, "fmi2SerializeFMUstate", NULL_ARGUMENT);
    b->worst = fmi2OK;
    size_t n = 0;
    fmi2Status s = combine(b, inner.SerializedFMUstateSize(b->inner, state, &n));
    if (s > fmi2Warning) return s;
    if (size < n) {
        char why[160];
        snprintf(why, sizeof why, LPV_BUFFER_TOO_SMALL, (unsigned long long)size, (unsigned long long)n);
        return refuse_argument(b, "fmi2SerializeFMUstate", why);
    }
    s = combine(b, inner.SerializeFMUstate(b->inner, state, bytes, n));
    if (size > n) memset(bytes + n, 0, size - n);
    return s;
}
EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                          fmi2FMUstate* state) {
    const size_t n = sizeof STATE_PREFIX - 1;
    CHECKED(c, "fmi2DeSerializeFMUstate", bytes && state && size >= n && memcmp(bytes, STATE_PREFIX, n) == 0,
            bytes && state ? LPV_NOT_A_STATE : NULL_ARGUMENT, inner.DeSerializeFMUstate(b_->inner, bytes, size, state));
}

static fmi2Status unsupported(fmi2Component c, const char* what) {
    Bridge* b = BRIDGE(c);
    if (b) {
        char msg[256];
        snprintf(msg, sizeof msg, "FMI function not supported: %s", what);
        report(b->host.logger, b->host.componentEnvironment, b->name, fmi2Error, msg);
    }
    return fmi2Error;
}

EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[], size_t nU,
                                               const fmi2ValueReference vKnown[], size_t nK, const fmi2Real dvKnown[],
                                               fmi2Real dvUnknown[]) {
    (void)vUnknown, (void)nU, (void)vKnown, (void)nK, (void)dvKnown, (void)dvUnknown;
    return unsupported(c, "fmi2GetDirectionalDerivative");
}
EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                              const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr, (void)nvr, (void)order, (void)value;
    return unsupported(c, "fmi2SetRealInputDerivatives");
}
EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                               const fmi2Integer order[], fmi2Real value[]) {
    (void)vr, (void)nvr, (void)order, (void)value;
    return unsupported(c, "fmi2GetRealOutputDerivatives");
}
EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                             fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Bridge* b = BRIDGE(c);
    if (!b) return fmi2Error;
    if (b->broken) return refuse_broken(b, "fmi2DoStep");
    b->worst = fmi2OK;
    fmi2Status s = inner.DoStep(b->inner, currentCommunicationPoint, communicationStepSize,
                                noSetFMUStatePriorToCurrentPoint);
    s = combine(b, s); /* after the call: the messages it logged set b->worst */
    if (s <= fmi2Warning) b->time = currentCommunicationPoint + communicationStepSize;
    return s;
}
EXPORT fmi2Status fmi2CancelStep(fmi2Component c) { return unsupported(c, "fmi2CancelStep"); }
/* a status the FMU does not have: fmi2Discard (FMI 2.0, 4.2.3), in the native FMUs' words */
static fmi2Status not_available(fmi2Component c, const char* what) {
    Bridge* b = BRIDGE(c);
    if (!b) return fmi2Error;
    char msg[300];
    snprintf(msg, sizeof msg, "%s: " LPV_STATUS_NOT_AVAILABLE, what);
    report(b->host.logger, b->host.componentEnvironment, b->name, fmi2Discard, msg);
    return fmi2Discard;
}

EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status* value) {
    (void)s, (void)value;
    return not_available(c, "fmi2GetStatus");
}
EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* value) {
    Bridge* b = BRIDGE(c);
    if (!b) return fmi2Error;
    if (!value) return refuse_argument(b, "fmi2GetRealStatus", NULL_ARGUMENT);
    if (s != fmi2LastSuccessfulTime) return not_available(c, "fmi2GetRealStatus");
    *value = b->time;
    return fmi2OK;
}
EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer* value) {
    (void)s, (void)value;
    return not_available(c, "fmi2GetIntegerStatus");
}
EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* value) {
    Bridge* b = BRIDGE(c);
    if (!b) return fmi2Error;
    if (!value) return refuse_argument(b, "fmi2GetBooleanStatus", NULL_ARGUMENT);
    if (s != fmi2Terminated) return not_available(c, "fmi2GetBooleanStatus");
    *value = fmi2False;
    return fmi2OK;
}
EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String* value) {
    (void)s, (void)value;
    return not_available(c, "fmi2GetStringStatus");
}
