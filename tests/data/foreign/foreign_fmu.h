/* What the foreign test FMUs (FMI 2.0 co-simulation, written in C, built by
 * tests/foreign_fmus.py) share: the instance, the state machine, logging, the
 * status queries and the calls they do not support.
 *
 * A model file defines MODEL_GUID and the type `Model` (its variables),
 * includes this file, then defines the hooks declared below: model_start
 * (start values), model_get and model_set (one variable: `type` is 'r', 'i',
 * 'b' or 's' for fmi2Real, fmi2Integer (Enumeration too), fmi2Boolean,
 * fmi2String, and `value` points to one value of that type) and model_step
 * (from the FMU's time t, h > 0). A hook that returns fmi2Error has logged
 * why. No globals: everything lives in the instance. C99, -Wall -Wextra
 * -Werror. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

typedef struct Instance Instance;
static void model_start(Model *m);
static fmi2Status model_get(Instance *s, char type, fmi2ValueReference vr, void *value);
static fmi2Status model_set(Instance *s, char type, fmi2ValueReference vr, const void *value);
static fmi2Status model_step(Instance *s, double t, double h);

enum State { INSTANTIATED, INITIALIZATION, STEPPING, STEP_FAILED, TERMINATED };

struct Instance {
    fmi2CallbackFunctions cb;
    char name[64];
    fmi2Boolean logging;
    enum State state;
    double time;            /* the FMU's time: fmi2LastSuccessfulTime */
    fmi2Boolean terminated; /* it asks to end the simulation: fmi2Terminated */
    Model model;
};

static void say(Instance *s, fmi2Status status, const char *fmt, ...) {
    char text[512];
    va_list ap;
    if (!s->logging && status < fmi2Warning) return;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    /* the message formatted here, as the FMI Reference FMUs pass it: no arguments */
    s->cb.logger(s->cb.componentEnvironment, s->name, status, status < fmi2Warning ? "logAll" : "logStatusError",
                 text);
}

/* a call allowed only in the states of `mask` (bits of enum State) */
static int allowed(Instance *s, const char *call, unsigned mask) {
    if (mask & (1u << s->state)) return 1;
    say(s, fmi2Error, "%s is not allowed in state %d", call, (int)s->state);
    return 0;
}
#define ANY ((1u << INSTANTIATED) | (1u << INITIALIZATION) | (1u << STEPPING) | (1u << STEP_FAILED) | (1u << TERMINATED))
#define GETTABLE ((1u << INITIALIZATION) | (1u << STEPPING) | (1u << STEP_FAILED) | (1u << TERMINATED))
#define SETTABLE ((1u << INSTANTIATED) | (1u << INITIALIZATION) | (1u << STEPPING))

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String categories[]) {
    (void)n, (void)categories;
    ((Instance *)c)->logging = on;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *cb, fmi2Boolean visible, fmi2Boolean logging) {
    Instance *s;
    (void)resources, (void)visible;
    if (!cb || !cb->logger || !cb->allocateMemory || !cb->freeMemory) return NULL;
    if (type != fmi2CoSimulation || !guid || strcmp(guid, MODEL_GUID) != 0) {
        cb->logger(cb->componentEnvironment, name, fmi2Error, "logStatusError",
                   "fmi2Instantiate: a co-simulation instance with GUID " MODEL_GUID " only");
        return NULL;
    }
    s = cb->allocateMemory(1, sizeof *s);
    if (!s) return NULL;
    s->cb = *cb;
    snprintf(s->name, sizeof s->name, "%s", name ? name : "?");
    s->logging = logging;
    s->state = INSTANTIATED;
    model_start(&s->model);
    return s;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *s = c;
    if (s) s->cb.freeMemory(s);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDefined, fmi2Real tol, fmi2Real start,
                               fmi2Boolean stopDefined, fmi2Real stop) {
    Instance *s = c;
    (void)tolDefined, (void)tol, (void)stopDefined, (void)stop;
    if (!allowed(s, "fmi2SetupExperiment", 1u << INSTANTIATED)) return fmi2Error;
    s->time = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    Instance *s = c;
    if (!allowed(s, "fmi2EnterInitializationMode", 1u << INSTANTIATED)) return fmi2Error;
    s->state = INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *s = c;
    if (!allowed(s, "fmi2ExitInitializationMode", 1u << INITIALIZATION)) return fmi2Error;
    s->state = STEPPING;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    Instance *s = c;
    if (!allowed(s, "fmi2Terminate", (1u << STEPPING) | (1u << STEP_FAILED))) return fmi2Error;
    s->state = TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Instance *s = c;
    s->state = INSTANTIATED;
    s->time = 0.0;
    s->terminated = fmi2False;
    model_start(&s->model);
    return fmi2OK;
}

#define ACCESS(Name, Ctype, code, mask, hook, CONST)                                                          \
    fmi2Status Name(fmi2Component c, const fmi2ValueReference vr[], size_t n, CONST Ctype value[]) {          \
        Instance *s = c;                                                                                      \
        size_t i;                                                                                             \
        if (!allowed(s, #Name, mask)) return fmi2Error;                                                       \
        for (i = 0; i < n; i++) {                                                                             \
            fmi2Status st = hook(s, code, vr[i], &value[i]);                                                  \
            if (st != fmi2OK) return st;                                                                      \
        }                                                                                                     \
        return fmi2OK;                                                                                        \
    }
#define NOCONST
ACCESS(fmi2GetReal, fmi2Real, 'r', GETTABLE, model_get, NOCONST)
ACCESS(fmi2GetInteger, fmi2Integer, 'i', GETTABLE, model_get, NOCONST)
ACCESS(fmi2GetBoolean, fmi2Boolean, 'b', GETTABLE, model_get, NOCONST)
ACCESS(fmi2GetString, fmi2String, 's', GETTABLE, model_get, NOCONST)
ACCESS(fmi2SetReal, fmi2Real, 'r', SETTABLE, model_set, const)
ACCESS(fmi2SetInteger, fmi2Integer, 'i', SETTABLE, model_set, const)
ACCESS(fmi2SetBoolean, fmi2Boolean, 'b', SETTABLE, model_set, const)
ACCESS(fmi2SetString, fmi2String, 's', SETTABLE, model_set, const)

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    Instance *s = c;
    (void)noSetPrior;
    if (!allowed(s, "fmi2DoStep", 1u << STEPPING)) return fmi2Error;
    if (!(h > 0.0) || t < s->time - 1e-9 * (1.0 + (s->time < 0 ? -s->time : s->time))
        || t > s->time + 1e-9 * (1.0 + (s->time < 0 ? -s->time : s->time))) {
        say(s, fmi2Error, "fmi2DoStep(%.17g, %.17g): expected the step from t = %.17g", t, h, s->time);
        return fmi2Error;
    }
    return model_step(s, t, h);
}

static fmi2Status unsupported(fmi2Component c, const char *call) {
    say(c, fmi2Error, "%s is not supported", call);
    return fmi2Error;
}

fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real *value) {
    Instance *s = c;
    if (k != fmi2LastSuccessfulTime) {
        say(s, fmi2Discard, "fmi2GetRealStatus: only fmi2LastSuccessfulTime is available");
        return fmi2Discard;
    }
    *value = s->time;
    return fmi2OK;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean *value) {
    Instance *s = c;
    if (k != fmi2Terminated) {
        say(s, fmi2Discard, "fmi2GetBooleanStatus: only fmi2Terminated is available");
        return fmi2Discard;
    }
    *value = s->terminated;
    return fmi2OK;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status *value) {
    (void)k, (void)value;
    say(c, fmi2Discard, "fmi2GetStatus: no asynchronous step");
    return fmi2Discard;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer *value) {
    (void)k, (void)value;
    say(c, fmi2Discard, "fmi2GetIntegerStatus: no status of this kind");
    return fmi2Discard;
}

fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String *value) {
    (void)k, (void)value;
    say(c, fmi2Discard, "fmi2GetStringStatus: no asynchronous step");
    return fmi2Discard;
}

fmi2Status fmi2CancelStep(fmi2Component c) { return unsupported(c, "fmi2CancelStep"); }

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    (void)state;
    return unsupported(c, "fmi2GetFMUstate");
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    (void)state;
    return unsupported(c, "fmi2SetFMUstate");
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    (void)state;
    return unsupported(c, "fmi2FreeFMUstate");
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t *size) {
    (void)state, (void)size;
    return unsupported(c, "fmi2SerializedFMUstateSize");
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size) {
    (void)state, (void)bytes, (void)size;
    return unsupported(c, "fmi2SerializeFMUstate");
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size, fmi2FMUstate *state) {
    (void)state, (void)bytes, (void)size;
    return unsupported(c, "fmi2DeSerializeFMUstate");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[],
                                        fmi2Real dz[]) {
    (void)u, (void)nu, (void)z, (void)nz, (void)dv, (void)dz;
    return unsupported(c, "fmi2GetDirectionalDerivative");
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr, (void)n, (void)order, (void)value;
    return unsupported(c, "fmi2SetRealInputDerivatives");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr, (void)n, (void)order, (void)value;
    return unsupported(c, "fmi2GetRealOutputDerivatives");
}
