/* A stand-in for pythonfmu's export library behind the lpvest status bridge (for
 * tests/test_status_bridge.py): it behaves as pythonfmu 0.7 does where the bridge
 * depends on it, without Python. Messages a call logs are queued and handed to the
 * logger at the end of the next call that drains (every call but fmi2Instantiate,
 * fmi2Reset and fmi2FreeInstance, as pythonfmu); fmi2Instantiate and fmi2Reset log
 * one message each (a slave that logs in its constructor). fmi2FreeInstance of an
 * instance with queued messages is counted (pythonfmu then passes them through a
 * destroyed logger). fmi2SetReal of a NaN logs at fmi2Error and returns fmi2OK (an
 * lpvest slave rejecting input); fmi2DoStep at t < 0 returns fmi2Fatal (a Python
 * exception). FMU states are 8 bytes, copied as pythonfmu does: fmi2SerializeFMUstate
 * copies as many bytes as the buffer size it is given (the size is recorded: a size
 * above 8 would read past the state), fmi2FreeFMUstate leaves *state set; live
 * states are counted. fmi2Instantiate records the resource location it got. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    void (*logger)(void*, const char*, int, const char*, const char*, ...);
    void* alloc;
    void* release;
    void* step;
    void* env;
} Callbacks;

typedef struct {
    const Callbacks* cb;
    int queued_status[8];
    const char* queued_text[8];
    int n;
} Instance;

static int frees = 0, frees_with_queue = 0, live_states = 0;
static size_t serialize_size = 0;
static char last_uri[4096];

int fake_frees(void) { return frees; }
int fake_frees_with_queue(void) { return frees_with_queue; }
int fake_live_states(void) { return live_states; }
size_t fake_serialize_size(void) { return serialize_size; }
const char* fake_last_uri(void) { return last_uri; }

static void queue(Instance* c, int status, const char* text) {
    if (c->n < 8) {
        c->queued_status[c->n] = status;
        c->queued_text[c->n++] = text;
    }
}

static void drain(Instance* c) {
    for (int i = 0; i < c->n; i++) c->cb->logger(c->cb->env, "fake", c->queued_status[i], "", c->queued_text[i]);
    c->n = 0;
}

void* fmi2Instantiate(const char* name, int type, const char* guid, const char* uri, const Callbacks* cb, int visible,
                      int logging) {
    (void)name, (void)type, (void)guid, (void)visible, (void)logging;
    strncpy(last_uri, uri ? uri : "(null)", sizeof last_uri - 1);
    Instance* c = (Instance*)calloc(1, sizeof(Instance));
    c->cb = cb;
    queue(c, 0, "constructed");
    return c;
}
void fmi2FreeInstance(void* p) {
    Instance* c = (Instance*)p;
    frees++;
    if (c->n) frees_with_queue++;
    free(c);
}
int fmi2Reset(void* p) {
    Instance* c = (Instance*)p;
    c->n = 0; /* the old slave's queue goes with it */
    queue(c, 0, "constructed again");
    return 0;
}
#define DRAINING(name, params)                  \
    int name params {                           \
        drain((Instance*)c);                    \
        return 0;                               \
    }
DRAINING(fmi2SetupExperiment, (void* c, int a, double b, double d, int e, double f))
DRAINING(fmi2EnterInitializationMode, (void* c))
DRAINING(fmi2ExitInitializationMode, (void* c))
DRAINING(fmi2Terminate, (void* c))
DRAINING(fmi2GetInteger, (void* c, const unsigned* vr, size_t n, int* v))
DRAINING(fmi2GetBoolean, (void* c, const unsigned* vr, size_t n, int* v))
DRAINING(fmi2GetString, (void* c, const unsigned* vr, size_t n, const char** v))
DRAINING(fmi2SetInteger, (void* c, const unsigned* vr, size_t n, const int* v))
DRAINING(fmi2SetBoolean, (void* c, const unsigned* vr, size_t n, const int* v))
DRAINING(fmi2SetString, (void* c, const unsigned* vr, size_t n, const char* const* v))
DRAINING(fmi2GetRealStatus, (void* c, int k, double* v))
int fmi2GetReal(void* c, const unsigned* vr, size_t n, double* v) {
    (void)vr;
    for (size_t i = 0; i < n; i++) v[i] = 1.0;
    drain((Instance*)c);
    return 0;
}
int fmi2SetReal(void* c, const unsigned* vr, size_t n, const double* v) {
    (void)vr;
    for (size_t i = 0; i < n; i++)
        if (isnan(v[i])) queue((Instance*)c, 3, "input = nan is not finite; value rejected (100%)");
    drain((Instance*)c);
    return 0;
}
int fmi2DoStep(void* c, double t, double h, int no_set) {
    (void)h, (void)no_set;
    if (t < 0) return 4; /* pythonfmu: a Python exception (it has released the slave's objects) */
    drain((Instance*)c);
    return 0;
}
int fmi2GetFMUstate(void* c, void** s) {
    *s = malloc(8);
    memcpy(*s, "STATE-01", 8);
    live_states++;
    drain((Instance*)c);
    return 0;
}
int fmi2SetFMUstate(void* c, void* s) {
    (void)s;
    drain((Instance*)c);
    return 0;
}
int fmi2FreeFMUstate(void* c, void** s) {
    free(*s); /* *s stays set, as pythonfmu leaves it */
    live_states--;
    drain((Instance*)c);
    return 0;
}
int fmi2SerializedFMUstateSize(void* c, void* s, size_t* n) {
    (void)s;
    *n = 8;
    drain((Instance*)c);
    return 0;
}
int fmi2SerializeFMUstate(void* c, void* s, char* b, size_t n) {
    serialize_size = n;
    memcpy(b, s, n < 8 ? n : 8);
    drain((Instance*)c);
    return 0;
}
int fmi2DeSerializeFMUstate(void* c, const char* b, size_t n, void** s) {
    (void)b, (void)n;
    return fmi2GetFMUstate(c, s);
}
