/*
 * A minimal FMI 2.0 co-simulation host in C, for the tests and as an example for
 * people writing their own (docs/fmus.md, "A host in C"): it loads an FMU's
 * library (dlopen / LoadLibrary), looks up the FMI functions and runs a script of
 * FMI calls read from standard input, one per line, printing every status and
 * value. No Python anywhere.
 *
 * usage: native_host LIBRARY GUID RESOURCES_URI < script
 *
 * Script lines (ID: an instance number 0..7):
 *   instantiate ID NAME LOGGING     fmi2Instantiate (LOGGING 0 or 1)
 *   setup ID T0 [STOP] | enter ID | exit ID | terminate ID | reset ID | free ID
 *   set_real ID VR VALUE            (VALUE as strtod reads it: 0.5, nan, inf)
 *   set_integer ID VR VALUE | set_boolean ID VR 0|1 | set_string ID VR TEXT
 *   get_real ID VR [VR ...]         prints: REAL v1 v2 ... (%.17g)
 *   get_integer ID VR | get_boolean ID VR | get_string ID VR
 *   step ID T H                     fmi2DoStep(T, H)
 *   step_here ID H                  fmi2DoStep(t, H) from the fmi2LastSuccessfulTime t the FMU reports
 *   time ID                         fmi2GetRealStatus(fmi2LastSuccessfulTime): TIME t
 *   get_state ID SLOT | set_state ID SLOT | free_state ID SLOT
 *   serialize ID SLOT               serialize the state in SLOT and deserialize it into SLOT again
 *   replace ID SLOT                 the same, deserialized into SLOT's variable over the state it
 *                                   holds, which is freed after (*FMUstate is an output only)
 *   unload / load                   close and open the library again
 *   set_string_back ID VR TEXT      fmi2SetString of VR to TEXT, then, in the same call, to the string
 *                                   fmi2GetString returned for VR before the call
 *   status ID KIND WHICH            fmi2Get<KIND>Status(WHICH) for KIND status|real|integer|boolean|string
 *                                   and WHICH 0..3; KIND real_null|boolean_null: a NULL value pointer
 *   debug ID ON N [CATEGORY ...]    fmi2SetDebugLogging(ON, N, the categories); none given: a NULL array
 *   locale NAME                     setlocale(LC_ALL, NAME): numbers are read and printed in it from now on
 *   state_null ID WHICH SLOT        an FMU-state call with one NULL argument, WHICH: get (the state
 *                                   pointer), set (the state), size_state/size_out (the state, the size
 *                                   pointer), serialize_state/serialize_buffer, deserialize_bytes/
 *                                   deserialize_out (the bytes, the state pointer); SLOT's state otherwise
 *   serialize_short ID SLOT LESS    fmi2SerializeFMUstate of SLOT's state into a buffer LESS bytes smaller
 *                                   than fmi2SerializedFMUstateSize says
 *   deserialize_text ID SLOT TEXT   fmi2DeSerializeFMUstate of TEXT's bytes into SLOT (its state freed
 *                                   when it worked)
 * instantiate ID NAME LOGGING [RESOURCES [GUID]] passes RESOURCES as fmuResourceLocation and GUID as
 * fmuGUID instead of those given on the command line ("=": the one given there).
 * In NAME and RESOURCES (instantiate), TEXT (set_string, deserialize_text) and CATEGORY, \xHH is
 * the byte HH and \null alone a NULL pointer: what a careless host may pass.
 * Each call prints "STATUS <command> <status>". The logger prints
 * "LOG <status> <category> <message>".
 */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <locale.h>

#ifdef _WIN32
#include <windows.h>
typedef HMODULE Library;
static Library open_library(const char* path) { return LoadLibraryA(path); }
static void* symbol(Library lib, const char* name) { return (void*)GetProcAddress(lib, name); }
static void close_library(Library lib) { FreeLibrary(lib); }
#else
#include <dlfcn.h>
typedef void* Library;
static Library open_library(const char* path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void* symbol(Library lib, const char* name) { return dlsym(lib, name); }
static void close_library(Library lib) { dlclose(lib); }
#endif

typedef void* fmi2Component;
typedef void* fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef void (*Logger)(void*, const char*, int, const char*, const char*, ...);
typedef struct {
    Logger logger;
    void* (*allocate)(size_t, size_t);
    void (*release)(void*);
    void* step_finished;
    void* env;
} Callbacks;

typedef fmi2Component (*Instantiate)(const char*, int, const char*, const char*, const Callbacks*, int, int);
typedef void (*FreeInstance)(fmi2Component);
typedef int (*Setup)(fmi2Component, int, double, double, int, double);
typedef int (*Mode)(fmi2Component);
typedef int (*SetReal)(fmi2Component, const fmi2ValueReference*, size_t, const double*);
typedef int (*GetReal)(fmi2Component, const fmi2ValueReference*, size_t, double*);
typedef int (*SetInteger)(fmi2Component, const fmi2ValueReference*, size_t, const int*);
typedef int (*GetInteger)(fmi2Component, const fmi2ValueReference*, size_t, int*);
typedef int (*SetString)(fmi2Component, const fmi2ValueReference*, size_t, const char* const*);
typedef int (*GetString)(fmi2Component, const fmi2ValueReference*, size_t, const char**);
typedef int (*DoStep)(fmi2Component, double, double, int);
typedef int (*GetRealStatus)(fmi2Component, int, double*);
typedef int (*GetIntStatus)(fmi2Component, int, int*);
typedef int (*GetStringStatus)(fmi2Component, int, const char**);
typedef int (*SetDebugLogging)(fmi2Component, int, size_t, const char* const*);
typedef int (*GetState)(fmi2Component, fmi2FMUstate*);
typedef int (*SetState)(fmi2Component, fmi2FMUstate);
typedef int (*FreeState)(fmi2Component, fmi2FMUstate*);
typedef int (*StateSize)(fmi2Component, fmi2FMUstate, size_t*);
typedef int (*Serialize)(fmi2Component, fmi2FMUstate, char*, size_t);
typedef int (*Deserialize)(fmi2Component, const char*, size_t, fmi2FMUstate*);

static struct {
    Library lib;
    Instantiate instantiate;
    FreeInstance free_instance;
    Setup setup;
    Mode enter, exit, terminate, reset;
    SetReal set_real;
    GetReal get_real;
    SetInteger set_integer, set_boolean;
    GetInteger get_integer, get_boolean;
    SetString set_string;
    GetString get_string;
    DoStep do_step;
    GetRealStatus get_real_status;
    GetIntStatus get_status, get_integer_status, get_boolean_status;
    GetStringStatus get_string_status;
    SetDebugLogging set_debug_logging;
    GetState get_state;
    SetState set_state;
    FreeState free_state;
    StateSize state_size;
    Serialize serialize;
    Deserialize deserialize;
} F;

static void logger(void* env, const char* name, int status, const char* category, const char* message, ...) {
    (void)env, (void)name;
    va_list ap;
    va_start(ap, message);
    printf("LOG %d %s ", status, category ? category : "");
    vprintf(message, ap);
    printf("\n");
    va_end(ap);
}

static int load(const char* path) {
    F.lib = open_library(path);
    if (!F.lib) return 0;
#define SYM(field, name)                                  \
    F.field = (void*)0;                                   \
    *(void**)(&F.field) = symbol(F.lib, name);            \
    if (!F.field) {                                       \
        printf("MISSING %s\n", name);                     \
        return 0;                                         \
    }
    SYM(instantiate, "fmi2Instantiate")
    SYM(free_instance, "fmi2FreeInstance")
    SYM(setup, "fmi2SetupExperiment")
    SYM(enter, "fmi2EnterInitializationMode")
    SYM(exit, "fmi2ExitInitializationMode")
    SYM(terminate, "fmi2Terminate")
    SYM(reset, "fmi2Reset")
    SYM(set_real, "fmi2SetReal")
    SYM(get_real, "fmi2GetReal")
    SYM(set_integer, "fmi2SetInteger")
    SYM(get_integer, "fmi2GetInteger")
    SYM(set_boolean, "fmi2SetBoolean")
    SYM(get_boolean, "fmi2GetBoolean")
    SYM(set_string, "fmi2SetString")
    SYM(get_string, "fmi2GetString")
    SYM(do_step, "fmi2DoStep")
    SYM(get_real_status, "fmi2GetRealStatus")
    SYM(get_status, "fmi2GetStatus")
    SYM(get_integer_status, "fmi2GetIntegerStatus")
    SYM(get_boolean_status, "fmi2GetBooleanStatus")
    SYM(get_string_status, "fmi2GetStringStatus")
    SYM(set_debug_logging, "fmi2SetDebugLogging")
    SYM(get_state, "fmi2GetFMUstate")
    SYM(set_state, "fmi2SetFMUstate")
    SYM(free_state, "fmi2FreeFMUstate")
    SYM(state_size, "fmi2SerializedFMUstateSize")
    SYM(serialize, "fmi2SerializeFMUstate")
    SYM(deserialize, "fmi2DeSerializeFMUstate")
    return 1;
}

/* text with \xHH decoded in place, or NULL for \null (see the top of this file) */
static char* decode(char* text) {
    if (strcmp(text, "\\null") == 0) return NULL;
    char* out = text;
    for (char* p = text; *p; p++) {
        unsigned x;
        if (p[0] == '\\' && p[1] == 'x' && sscanf(p + 2, "%2x", &x) == 1) {
            *out++ = (char)x;
            p += 3;
        } else {
            *out++ = *p;
        }
    }
    *out = '\0';
    return text;
}

#define N_INSTANCES 8
#define N_SLOTS 8

int main(int argc, char** argv) {
    if (argc != 4) {
        fprintf(stderr, "usage: native_host LIBRARY GUID RESOURCES_URI < script\n");
        return 2;
    }
    setvbuf(stdout, NULL, _IOLBF, 1 << 16);
    if (!load(argv[1])) {
        printf("LOADFAIL\n");
        return 3;
    }
    Callbacks cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c[N_INSTANCES] = {0};
    fmi2FMUstate states[N_INSTANCES][N_SLOTS] = {{0}};
    char line[4096];
    while (fgets(line, sizeof line, stdin)) {
        char cmd[64] = {0};
        int id = 0, n = 0;
        if (sscanf(line, "%63s%n", cmd, &n) != 1) continue;
        char* rest = line + n;
        if (strcmp(cmd, "unload") == 0) {
            close_library(F.lib);
            printf("STATUS unload 0\n");
            fflush(stdout);
            continue;
        }
        if (strcmp(cmd, "locale") == 0) {
            char name[128] = {0};
            sscanf(line + n, "%127s", name);
            printf("STATUS locale %d\n", setlocale(LC_ALL, name) ? 0 : 1);
            fflush(stdout);
            continue;
        }
        if (strcmp(cmd, "load") == 0) {
            printf("STATUS load %d\n", load(argv[1]) ? 0 : 4);
            fflush(stdout);
            continue;
        }
        int m = 0;
        if (sscanf(rest, "%d%n", &id, &m) != 1 || id < 0 || id >= N_INSTANCES) {
            printf("BADLINE %s", line);
            fflush(stdout);
            continue;
        }
        rest += m;
        int st = 0;
        if (strcmp(cmd, "instantiate") == 0) {
            char name[256], resources[1024], guid[1024];
            int logging = 0;
            int got = sscanf(rest, "%255s %d %1023s %1023s", name, &logging, resources, guid);
            const char* uri = got >= 3 && strcmp(resources, "=") != 0 ? decode(resources) : argv[3];
            const char* id_guid = got >= 4 && strcmp(guid, "=") != 0 ? decode(guid) : argv[2];
            c[id] = F.instantiate(decode(name), 1, id_guid, uri, &cb, 0, logging);
            printf("STATUS instantiate %s\n", c[id] ? "0" : "null");
            fflush(stdout);
            continue;
        } else if (strcmp(cmd, "free") == 0) {
            for (int slot = 0; slot < N_SLOTS; slot++) /* an instance's states go with it */
                if (states[id][slot]) F.free_state(c[id], &states[id][slot]);
            F.free_instance(c[id]);
            c[id] = NULL;
            printf("STATUS free 0\n");
            fflush(stdout);
            continue;
        } else if (strcmp(cmd, "setup") == 0) {
            char *end, *after;
            double t0 = strtod(rest, &end), stop = strtod(end, &after); /* a stop time when given */
            st = F.setup(c[id], 0, 0.0, t0, after != end, stop);
        } else if (strcmp(cmd, "enter") == 0) {
            st = F.enter(c[id]);
        } else if (strcmp(cmd, "exit") == 0) {
            st = F.exit(c[id]);
        } else if (strcmp(cmd, "terminate") == 0) {
            st = F.terminate(c[id]);
        } else if (strcmp(cmd, "reset") == 0) {
            st = F.reset(c[id]);
        } else if (strcmp(cmd, "set_real") == 0) {
            char* end;
            fmi2ValueReference vr = (fmi2ValueReference)strtoul(rest, &end, 10);
            double v = strtod(end, NULL);
            st = F.set_real(c[id], &vr, 1, &v);
        } else if (strcmp(cmd, "set_integer") == 0 || strcmp(cmd, "set_boolean") == 0) {
            char* end;
            fmi2ValueReference vr = (fmi2ValueReference)strtoul(rest, &end, 10);
            int v = (int)strtol(end, NULL, 10);
            st = (cmd[4] == 'i' ? F.set_integer : F.set_boolean)(c[id], &vr, 1, &v);
        } else if (strcmp(cmd, "set_string") == 0) {
            char* end;
            fmi2ValueReference vr = (fmi2ValueReference)strtoul(rest, &end, 10);
            while (*end == ' ') end++;
            end[strcspn(end, "\r\n")] = '\0';
            const char* v = decode(end);
            st = F.set_string(c[id], &vr, 1, &v);
        } else if (strcmp(cmd, "set_string_back") == 0) {
            char* end;
            fmi2ValueReference vr = (fmi2ValueReference)strtoul(rest, &end, 10);
            while (*end == ' ') end++;
            end[strcspn(end, "\r\n")] = '\0';
            const char* before = "";
            st = F.get_string(c[id], &vr, 1, &before);
            fmi2ValueReference vrs[2] = {vr, vr};
            const char* values[2] = {decode(end), before};
            if (st <= 1) st = F.set_string(c[id], vrs, 2, values);
        } else if (strcmp(cmd, "get_real") == 0) {
            fmi2ValueReference vrs[512];
            double v[512];
            size_t k = 0;
            char* p = rest;
            char* end;
            while (k < 512) {
                unsigned long x = strtoul(p, &end, 10);
                if (end == p) break;
                vrs[k++] = (fmi2ValueReference)x;
                p = end;
            }
            st = F.get_real(c[id], vrs, k, v);
            printf("REAL");
            for (size_t i = 0; i < k; i++) printf(" %.17g", v[i]);
            printf("\n");
        } else if (strcmp(cmd, "get_integer") == 0 || strcmp(cmd, "get_boolean") == 0) {
            fmi2ValueReference vr = (fmi2ValueReference)strtoul(rest, NULL, 10);
            int v = 0;
            st = (cmd[4] == 'i' ? F.get_integer : F.get_boolean)(c[id], &vr, 1, &v);
            printf("INT %d\n", v);
        } else if (strcmp(cmd, "get_string") == 0) {
            fmi2ValueReference vr = (fmi2ValueReference)strtoul(rest, NULL, 10);
            const char* v = "";
            st = F.get_string(c[id], &vr, 1, &v);
            printf("STRING %s\n", v ? v : "(null)");
        } else if (strcmp(cmd, "status") == 0) {
            char kind[32] = {0};
            int which = 0;
            sscanf(rest, "%31s %d", kind, &which);
            int v = -1;
            double t = -1.0;
            const char* text = "(unset)";
            if (strcmp(kind, "status") == 0) st = F.get_status(c[id], which, &v);
            else if (strcmp(kind, "integer") == 0) st = F.get_integer_status(c[id], which, &v);
            else if (strcmp(kind, "boolean") == 0) st = F.get_boolean_status(c[id], which, &v);
            else if (strcmp(kind, "boolean_null") == 0) st = F.get_boolean_status(c[id], which, NULL);
            else if (strcmp(kind, "real") == 0) st = F.get_real_status(c[id], which, &t);
            else if (strcmp(kind, "real_null") == 0) st = F.get_real_status(c[id], which, NULL);
            else st = F.get_string_status(c[id], which, &text);
            printf("VALUES %d %.17g %s\n", v, t, text ? text : "(null)");
        } else if (strcmp(cmd, "debug") == 0) {
            int on = 0, count = 0, used = 0;
            sscanf(rest, "%d %d%n", &on, &count, &used);
            char* names[16];
            char words[16][128];
            int k = 0;
            for (char* p = rest + used; k < 16 && sscanf(p, "%127s%n", words[k], &used) == 1; p += used, k++)
                names[k] = decode(words[k]);
            st = F.set_debug_logging(c[id], on, (size_t)count, k ? (const char* const*)names : NULL);
        } else if (strcmp(cmd, "step") == 0) {
            char* end;
            double t = strtod(rest, &end);
            double h = strtod(end, NULL);
            st = F.do_step(c[id], t, h, 1);
        } else if (strcmp(cmd, "step_here") == 0) { /* a step from the time the FMU reports */
            double t = 0.0;
            F.get_real_status(c[id], 2, &t);
            st = F.do_step(c[id], t, strtod(rest, NULL), 1);
        } else if (strcmp(cmd, "time") == 0) {
            double t = 0.0;
            st = F.get_real_status(c[id], 2, &t);
            printf("TIME %.17g\n", t);
        } else if (strcmp(cmd, "state_null") == 0) {
            char which[32] = {0};
            int slot = 0;
            sscanf(rest, "%31s %d", which, &slot);
            fmi2FMUstate state = slot >= 0 && slot < N_SLOTS ? states[id][slot] : NULL, made = NULL;
            size_t size = 0;
            char bytes[16] = "LPVSTAT2";
            if (strcmp(which, "get") == 0) st = F.get_state(c[id], NULL);
            else if (strcmp(which, "set") == 0) st = F.set_state(c[id], NULL);
            else if (strcmp(which, "size_state") == 0) st = F.state_size(c[id], NULL, &size);
            else if (strcmp(which, "size_out") == 0) st = F.state_size(c[id], state, NULL);
            else if (strcmp(which, "serialize_state") == 0) st = F.serialize(c[id], NULL, bytes, sizeof bytes);
            else if (strcmp(which, "serialize_buffer") == 0) st = F.serialize(c[id], state, NULL, 1u << 20);
            else if (strcmp(which, "deserialize_bytes") == 0) st = F.deserialize(c[id], NULL, 8, &made);
            else if (strcmp(which, "deserialize_out") == 0) st = F.deserialize(c[id], bytes, 8, NULL);
            else {
                printf("BADLINE %s", line);
                fflush(stdout);
                continue;
            }
            if (made) F.free_state(c[id], &made);
        } else if (strcmp(cmd, "serialize_short") == 0) {
            int slot = 0;
            unsigned long less = 0;
            sscanf(rest, "%d %lu", &slot, &less);
            size_t size = 0;
            st = F.state_size(c[id], slot >= 0 && slot < N_SLOTS ? states[id][slot] : NULL, &size);
            char* bytes = (char*)malloc(size + 1);
            if (!st) st = F.serialize(c[id], states[id][slot], bytes, size > less ? size - less : 0);
            free(bytes);
        } else if (strcmp(cmd, "deserialize_text") == 0) {
            int slot = 0, used = 0;
            sscanf(rest, "%d %n", &slot, &used);
            char* text = rest + used;
            text[strcspn(text, "\r\n")] = '\0';
            size_t n = strlen(text); /* the bytes before decoding shortens them; \x00 ends them */
            const char* bytes = decode(text);
            fmi2FMUstate made = NULL;
            st = F.deserialize(c[id], bytes, bytes ? strlen(bytes) : n, &made);
            if (!st && slot >= 0 && slot < N_SLOTS) {
                if (states[id][slot]) F.free_state(c[id], &states[id][slot]);
                states[id][slot] = made;
            } else if (made) {
                F.free_state(c[id], &made);
            }
        } else if (strcmp(cmd, "get_state") == 0 || strcmp(cmd, "set_state") == 0 || strcmp(cmd, "free_state") == 0 ||
                   strcmp(cmd, "serialize") == 0 || strcmp(cmd, "replace") == 0) {
            int slot = atoi(rest);
            if (slot < 0 || slot >= N_SLOTS) {
                printf("BADLINE %s", line);
                fflush(stdout);
                continue;
            }
            if (cmd[0] == 'g') st = F.get_state(c[id], &states[id][slot]);
            else if (cmd[0] == 's' && cmd[1] == 'e' && cmd[2] == 't') st = F.set_state(c[id], states[id][slot]);
            else if (cmd[0] == 'f') st = F.free_state(c[id], &states[id][slot]);
            else {
                size_t size = 0;
                st = F.state_size(c[id], states[id][slot], &size);
                char* bytes = (char*)malloc(size ? size : 1);
                if (!st) st = F.serialize(c[id], states[id][slot], bytes, size);
                fmi2FMUstate copy = NULL;
                if (cmd[0] == 'r') {
                    fmi2FMUstate old = states[id][slot];
                    if (!st) st = F.deserialize(c[id], bytes, size, &states[id][slot]);
                    if (!st && old) F.free_state(c[id], &old);
                } else {
                    if (!st) st = F.deserialize(c[id], bytes, size, &copy);
                    if (!st) {
                        F.free_state(c[id], &states[id][slot]);
                        states[id][slot] = copy;
                    }
                }
                free(bytes);
                printf("SIZE %lu\n", (unsigned long)size);
            }
        } else {
            printf("BADLINE %s", line);
            fflush(stdout);
            continue;
        }
        printf("STATUS %s %d\n", cmd, st);
        fflush(stdout); /* a pipe: every answer now (Windows' C runtime buffers whole blocks, even "by line") */
    }
    for (int i = 0; i < N_INSTANCES; i++)
        if (c[i]) {
            for (int s = 0; s < N_SLOTS; s++)
                if (states[i][s]) F.free_state(c[i], &states[i][s]);
            F.free_instance(c[i]);
        }
    printf("DONE\n");
    return 0;
}
