/* AllTypes: a foreign FMI 2.0 co-simulation FMU (not made by lpvest) with a
 * parameter, an input and an output of every FMI 2.0 type, each output a
 * function of the input of its type at the same instant (direct feedthrough):
 *
 *   real_out   = gain * real_in                      Real
 *   int_out    = int_in + offset                     Integer
 *   enum_out   = max(enum_in, floor_level)           Enumeration Level (low 1, mid 2, high 3)
 *   bool_out   = bool_in xor invert                  Boolean
 *   string_out = prefix + string_in                  String
 *
 * and `steps` (Integer output, no input) counts the steps taken. Value
 * references start at 0 for each type, as FMI 2.0 allows (Enumeration shares
 * Integer's): a master that reads a variable with the wrong type's call gets
 * another variable's value. Model description: all_types.xml. */
#define MODEL_GUID "{1d1b0b38-4c3e-4a57-9d0e-a11c7e5e0001}"
#define TEXT 64

typedef struct Model {
    double gain, real_in;
    int offset, int_in, steps, floor_level, enum_in;
    int invert, bool_in;
    char prefix[TEXT], string_in[TEXT], string_out[2 * TEXT];
} Model;

#include "foreign_fmu.h"

static void model_start(Model *m) {
    memset(m, 0, sizeof *m);
    m->gain = 2.0;
    m->offset = 1;
    m->floor_level = 1;
    m->enum_in = 1;
    strcpy(m->prefix, "in:");
}

static fmi2Status model_get(Instance *s, char type, fmi2ValueReference vr, void *value) {
    Model *m = &s->model;
    switch (type) {
    case 'r': {
        double v[] = {m->gain, m->real_in, m->gain * m->real_in};
        if (vr > 2) break;
        *(fmi2Real *)value = v[vr];
        return fmi2OK;
    }
    case 'i': {
        int v[] = {m->offset, m->int_in, m->int_in + m->offset, m->steps, m->floor_level, m->enum_in,
                   m->enum_in > m->floor_level ? m->enum_in : m->floor_level};
        if (vr > 6) break;
        *(fmi2Integer *)value = v[vr];
        return fmi2OK;
    }
    case 'b': {
        int v[] = {m->invert, m->bool_in, m->bool_in != m->invert};
        if (vr > 2) break;
        *(fmi2Boolean *)value = v[vr] ? fmi2True : fmi2False;
        return fmi2OK;
    }
    case 's':
        if (vr > 2) break;
        snprintf(m->string_out, sizeof m->string_out, "%s%s", m->prefix, m->string_in);
        *(fmi2String *)value = vr == 0 ? m->prefix : vr == 1 ? m->string_in : m->string_out;
        return fmi2OK;
    }
    say(s, fmi2Error, "no variable of type '%c' with value reference %u", type, (unsigned)vr);
    return fmi2Error;
}

static fmi2Status model_set(Instance *s, char type, fmi2ValueReference vr, const void *value) {
    Model *m = &s->model;
    int parameter = vr == 0 || (type == 'i' && vr == 4);
    if (parameter && s->state != INSTANTIATED && s->state != INITIALIZATION) {
        say(s, fmi2Error, "the parameter of type '%c' with value reference %u is fixed", type, (unsigned)vr);
        return fmi2Error;
    }
    switch (type) {
    case 'r':
        if (vr == 0) m->gain = *(const fmi2Real *)value;
        else if (vr == 1) m->real_in = *(const fmi2Real *)value;
        else break;
        return fmi2OK;
    case 'i': {
        int v = *(const fmi2Integer *)value;
        if ((vr == 4 || vr == 5) && (v < 1 || v > 3)) {
            say(s, fmi2Error, "%s = %d is not a Level (1, 2 or 3)", vr == 4 ? "floor_level" : "enum_in", v);
            return fmi2Error;
        }
        if (vr == 0) m->offset = v;
        else if (vr == 1) m->int_in = v;
        else if (vr == 4) m->floor_level = v;
        else if (vr == 5) m->enum_in = v;
        else break;
        return fmi2OK;
    }
    case 'b':
        if (vr == 0) m->invert = *(const fmi2Boolean *)value != fmi2False;
        else if (vr == 1) m->bool_in = *(const fmi2Boolean *)value != fmi2False;
        else break;
        return fmi2OK;
    case 's': {
        fmi2String v = *(const fmi2String *)value;
        if (vr > 1) break;
        if (!v || strlen(v) >= TEXT) {
            say(s, fmi2Error, "%s: expected a string of fewer than %d bytes", vr == 0 ? "prefix" : "string_in", TEXT);
            return fmi2Error;
        }
        strcpy(vr == 0 ? m->prefix : m->string_in, v);
        return fmi2OK;
    }
    }
    say(s, fmi2Error, "no settable variable of type '%c' with value reference %u", type, (unsigned)vr);
    return fmi2Error;
}

static fmi2Status model_step(Instance *s, double t, double h) {
    s->time = t + h;
    s->model.steps++;
    return fmi2OK;
}
