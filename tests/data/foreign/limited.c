/* Limited: a foreign FMI 2.0 co-simulation FMU (not made by lpvest) that is
 * valid up to a time of its own, as the FMI Reference FMU Stair is: `counter`
 * (Integer output) counts the whole time units passed (an event at t = 1, 2,
 * ...), and when it reaches the parameter `last` the step stops at that event
 * and returns fmi2Discard, with fmi2LastSuccessfulTime the event's time and
 * fmi2Terminated the parameter `terminate` (true: the FMU asks to end the
 * simulation; false: it only could not complete the step). Also `time_out`
 * (Real output: the FMU's time) and y = u (Real, direct feedthrough).
 * Model description: limited.xml. */
#define MODEL_GUID "{1d1b0b38-4c3e-4a57-9d0e-a11c7e5e0002}"

typedef struct Model {
    int counter, last, terminate;
    double u;
} Model;

#include "foreign_fmu.h"

static void model_start(Model *m) {
    m->counter = 0;
    m->last = 5;
    m->terminate = 1;
    m->u = 0.0;
}

static fmi2Status model_get(Instance *s, char type, fmi2ValueReference vr, void *value) {
    Model *m = &s->model;
    if (type == 'r' && vr <= 2) {
        *(fmi2Real *)value = vr == 0 ? s->time : m->u; /* vr 1: u, vr 2: y = u */
        return fmi2OK;
    }
    if (type == 'i' && vr <= 1) {
        *(fmi2Integer *)value = vr == 0 ? m->counter : m->last;
        return fmi2OK;
    }
    if (type == 'b' && vr == 0) {
        *(fmi2Boolean *)value = m->terminate ? fmi2True : fmi2False;
        return fmi2OK;
    }
    say(s, fmi2Error, "no variable of type '%c' with value reference %u", type, (unsigned)vr);
    return fmi2Error;
}

static fmi2Status model_set(Instance *s, char type, fmi2ValueReference vr, const void *value) {
    Model *m = &s->model;
    if (type == 'r' && vr == 1) {
        m->u = *(const fmi2Real *)value;
        return fmi2OK;
    }
    if ((type == 'i' && vr == 1) || (type == 'b' && vr == 0)) {
        if (s->state != INSTANTIATED && s->state != INITIALIZATION) {
            say(s, fmi2Error, "%s is a fixed parameter", type == 'i' ? "last" : "terminate");
            return fmi2Error;
        }
        if (type == 'i') m->last = *(const fmi2Integer *)value;
        else m->terminate = *(const fmi2Boolean *)value != fmi2False;
        return fmi2OK;
    }
    say(s, fmi2Error, "no settable variable of type '%c' with value reference %u", type, (unsigned)vr);
    return fmi2Error;
}

static fmi2Status model_step(Instance *s, double t, double h) {
    Model *m = &s->model;
    double end = t + h, tol = 1e-9 * (1.0 + (end < 0 ? -end : end));
    double event = (double)(m->counter + 1);
    while (event <= end + tol) {
        s->time = event;
        m->counter++;
        if (m->counter >= m->last) {
            s->terminated = m->terminate ? fmi2True : fmi2False;
            s->state = STEP_FAILED;
            say(s, fmi2Discard, "counter reached %d at t = %g: %s", m->counter, s->time,
                m->terminate ? "the end of this model's validity" : "cannot step past this point");
            return fmi2Discard;
        }
        event += 1.0;
    }
    s->time = end;
    return fmi2OK;
}
