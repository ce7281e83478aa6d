/*
 * lpvest native runtime: the FMI 2.0 co-simulation layer.
 *
 * What lpvest/fmi/_slave.py (the Python FMU's base, behind lpvest's status bridge)
 * does, for the roles of this runtime: the same variables (lpv_model_data), the
 * same step semantics, the same refusals with the same messages and statuses,
 * FMU states. In brief (docs/fmus.md states it for both backends):
 *
 * - One instance struct per fmi2Instantiate, no global state. Every FMI call
 *   returns the most severe status of the messages it logged (fmi2OK when none);
 *   messages of status warning or worse always reach the host, the others when
 *   logging is on for their category.
 * - fmi2SetReal checks each element where it enters (finite, within its declared
 *   range): a rejected value is not stored, it is remembered as invalid (named by
 *   a step refused while it stands) until a valid value is set.
 * - Outputs are computed on demand: after the inputs of sample k are set, an
 *   output reads its value at sample k. fmi2DoStep(t_k, h), h = m sample times,
 *   consumes m samples with the inputs held; afterwards an output that feeds
 *   through (port.direct) holds the value of the last sample consumed until an
 *   input is set, the others read their value at t_k + h. A step that is not a
 *   valid next step (h <= 0 or not finite, not a whole number of samples, not at
 *   the FMU's time, after fmi2Terminate, with an invalid value set, an output that
 *   is not finite) is fmi2Error and consumes nothing.
 * - A filter's measurement may arrive late (parameter measurement_delay = d): it is
 *   paired with the other inputs of its own sample, kept from d samples before
 *   (lpvest.protocol.MeasurementDelay); every output is 0 until the first pair.
 * - Memory is allocated in fmi2Instantiate, when the component is configured
 *   (fmi2ExitInitializationMode, a preview of the outputs before it, fmi2SetFMUstate)
 *   and for FMU states; never in fmi2DoStep, fmi2GetReal or fmi2SetReal.
 */
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "lpv.h"
#include "lpv_host_words.h"

/* the relative tolerance of communication points (lpvest.fmi.slave._TIME_RTOL), at most h / 2 */
#define TIME_RTOL 1e-9

/* why a value was rejected */
enum { REJECT_NONE = 0, REJECT_NONFINITE = 1, REJECT_RANGE = 2 };

/* the log categories of the model description (pythonfmu's) */
static const char* const CATEGORIES[] = {"logStatusWarning", "logStatusDiscard", "logStatusError",
                                         "logStatusFatal", "logAll"};
#define N_CATEGORIES 5

typedef struct {
    const lpv_role* role;
    lpv_comp comp;
    int ready;   /* configured */
    int delay;   /* measurement delay (samples) */
    int n_queue; /* on-time samples kept (<= delay) */
    int head;    /* oldest kept sample */
    double* queue;  /* delay x n_inputs (only the on-time elements are used) */
    double* paired; /* n_inputs */
    int paired_now; /* the last evaluation stepped the inner component */
    /* the state before a step of several samples (restored when one of them fails) */
    double* backup_st;
    uint64_t* backup_words;
    double* backup_queue;
    double backup_t;
    int backup_nq, backup_head;
} component;

typedef struct {
    const lpv_model* m;
    fmi2CallbackFunctions cb;
    char* name;
    int logging_on;
    unsigned categories; /* bit i: CATEGORIES[i] enabled */
    fmi2Status worst;    /* of the messages logged in the current call */

    double* reals;
    int* ints;
    int* bools;
    char** strings;
    double* inputs;
    double* outputs;
    double* held;
    double* scratch_out; /* n_outputs: samples 2..m of a step */
    int held_valid;
    int pending; /* comp's tmp holds the evaluation of the current inputs */
    /* of the model, counted once at instantiation (fmi2DoStep asks every step) */
    int feedthrough; /* has_feedthrough(m) */
    int all_direct;  /* every output port has direct feedthrough */

    int* invalid; /* value references, in the order they became invalid */
    int n_invalid;
    unsigned char* reason; /* per variable */
    double* rejected_real;
    int* rejected_int;

    int initialized, terminated, dirty;
    int entered; /* fmi2EnterInitializationMode was called (until a reset) */
    int n_nonfinite;
    double time, start_time;
    int announced;    /* the version message was logged (once after fmi2Instantiate or fmi2Reset, as the
                         Python slaves log what their constructor logged, at fmi2SetupExperiment) */
    int stop_defined; /* fmi2SetupExperiment's stop time, when defined: no step ends after it */
    double stop_time;
    char init_error[LPV_MSG + 32]; /* "initialization failed: " and a message */

    component comp;
    component preview;
    int preview_valid;
    double model_params[LPV_MAX_MODEL_PARAMS];
    lpv_msg msg;
} instance;

/* ------------------------------------------------------------- logging */

static int category_bit(fmi2Status st) {
    switch (st) {
    case fmi2Warning: return 0;
    case fmi2Discard: return 1;
    case fmi2Error: return 2;
    case fmi2Fatal: return 3;
    default: return 4;
    }
}

/* log a message (the Python slave's _log: cut to LPV_MAX_MESSAGE, prefixed with the model name) */
static void logm(instance* s, fmi2Status st, const char* text) {
    if (st > s->worst && st <= fmi2Error) s->worst = st;
    int bit = category_bit(st);
    int forward = st >= fmi2Warning || (s->logging_on && (s->categories & (1u << bit)));
    if (!forward || !s->cb.logger) return;
    char body[LPV_MSG + 64];
    size_t len = strlen(text);
    if (len > LPV_MAX_MESSAGE) {
        size_t keep = LPV_MAX_MESSAGE - 40;
        snprintf(body, sizeof body, "%.*s ... (%lu characters cut)", (int)keep, text, (unsigned long)(len - keep));
    } else {
        snprintf(body, sizeof body, "%s", text);
    }
    /* the host receives a format string without arguments: every '%' doubled */
    char out[2 * (LPV_MSG + 64) + 64];
    size_t pos = (size_t)snprintf(out, sizeof out, "[%s] ", s->m->identifier);
    for (const char* p = body; *p && pos + 3 < sizeof out; p++) {
        out[pos++] = *p;
        if (*p == '%') out[pos++] = '%';
    }
    out[pos] = '\0';
    s->cb.logger(s->cb.componentEnvironment, s->name ? s->name : "", st, CATEGORIES[bit], out);
}

static void logf_(instance* s, fmi2Status st, const char* fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 3, 4)))
#endif
    ;
static void logf_(instance* s, fmi2Status st, const char* fmt, ...) {
    char text[LPV_MSG * 2];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(text, sizeof text, fmt, ap);
    va_end(ap);
    logm(s, st, text);
}

#define BEGIN(c)                                  \
    instance* s = (instance*)(c);                 \
    if (!s) return fmi2Error;                     \
    s->worst = fmi2OK
#define END return s->worst
/* a getter or setter given nvr > 0 and a NULL array: refused before any element is read */
#define REFUSE_NULL_ARRAYS(what)                         \
    if (nvr && (!vr || !value)) {                        \
        logf_(s, fmi2Error, what ": a null array");      \
        END;                                             \
    }

/* ----------------------------------------------------------- components */

static const lpv_role* role_of(const lpv_model* m) {
    switch (m->role) {
    case LPV_ROLE_PLANT: return lpv_role_plant();
    case LPV_ROLE_SCHEDULER: return lpv_role_scheduler();
    case LPV_ROLE_SOURCE: return lpv_role_source();
    case LPV_ROLE_KALMAN: return lpv_role_kalman();
    case LPV_ROLE_TRUNCATED: return lpv_role_truncated();
    case LPV_ROLE_HINF: return lpv_role_hinf();
    default: return NULL;
    }
}

static lpv_values values_of(const instance* s) {
    lpv_values v;
    v.reals = s->reals;
    v.ints = s->ints;
    v.bools = s->bools;
    v.strings = (const char* const*)s->strings;
    return v;
}

static void comp_free(component* c) {
    free(c->comp.mem);
    free(c->queue);
    free(c->paired);
    free(c->backup_st);
    free(c->backup_words);
    free(c->backup_queue);
    memset(c, 0, sizeof *c);
}

static void* zalloc(size_t n, size_t size) { return calloc(n ? n : 1, size ? size : 1); }

static size_t align8(size_t n) { return (n + 7u) & ~(size_t)7u; }

/* build a component from the current parameters (the Python slave's make_component) */
static int comp_configure(instance* s, component* c, lpv_msg* err) {
    comp_free(c);
    const lpv_model* m = s->m;
    c->role = role_of(m);
    if (!c->role) {
        lpv_msgf(err, "LpvestError: this FMU's role %d is unknown to the runtime", m->role);
        return 1;
    }
    for (int i = 0; i < m->n_model_params; i++) s->model_params[i] = s->reals[m->model_params[i]];
    lpv_values v = values_of(s);
    lpv_sizes z;
    memset(&z, 0, sizeof z);
    if (c->role->sizes(m, &v, s->model_params, &z, err)) return 1;
    size_t bytes = sizeof(double) * (align8(z.n_cfg) + align8(z.n_st) + align8(z.n_tmp)) +
                   sizeof(uint64_t) * align8(z.n_words) + sizeof(int) * align8(z.n_itmp) + 64;
    void* mem = calloc(1, bytes);
    if (!mem) {
        lpv_msgf(err, "MemoryError: cannot allocate %lu bytes for this configuration", (unsigned long)bytes);
        return 1;
    }
    lpv_comp* k = &c->comp;
    memset(k, 0, sizeof *k);
    k->model = m;
    k->mem = mem;
    double* d = (double*)mem;
    k->cfg = d, k->n_cfg = z.n_cfg, d += align8(z.n_cfg);
    k->st = d, k->n_st = z.n_st, d += align8(z.n_st);
    k->tmp = d, k->n_tmp = z.n_tmp, d += align8(z.n_tmp);
    k->words = (uint64_t*)d, k->n_words = z.n_words;
    k->itmp = (int*)(k->words + align8(z.n_words)), k->n_itmp = z.n_itmp;
    if (c->role->configure(k, &v, s->model_params, err)) {
        comp_free(c);
        return 1;
    }
    c->delay = m->measurement_delay >= 0 ? s->ints[m->measurement_delay] : 0;
    if (c->delay > 0) {
        /* at most 2^40 bytes, and what size_t holds (32-bit targets: a shift by 40 of a size_t is undefined) */
        uint64_t per_sample = (uint64_t)sizeof(double) * (uint64_t)(m->n_inputs + 1);
        if ((uint64_t)c->delay > ((uint64_t)1 << 40) / per_sample ||
            (uint64_t)c->delay * per_sample > (uint64_t)SIZE_MAX) {
            lpv_msgf(err, "MemoryError: measurement_delay = %d: cannot keep that many samples", c->delay);
            comp_free(c);
            return 1;
        }
        c->queue = (double*)calloc((size_t)c->delay * (size_t)(m->n_inputs + 1), sizeof(double));
        c->paired = (double*)calloc((size_t)m->n_inputs + 1, sizeof(double));
        if (!c->queue || !c->paired) {
            lpv_msgf(err, "MemoryError: measurement_delay = %d: cannot keep that many samples", c->delay);
            comp_free(c);
            return 1;
        }
    }
    c->backup_st = (double*)zalloc(k->n_st, sizeof(double));
    c->backup_words = (uint64_t*)zalloc(k->n_words, sizeof(uint64_t));
    c->backup_queue = (double*)zalloc((size_t)c->delay * (size_t)m->n_inputs, sizeof(double));
    if (!c->backup_st || !c->backup_words || !c->backup_queue) {
        lpv_msgf(err, "MemoryError: cannot allocate the state of this configuration");
        comp_free(c);
        return 1;
    }
    c->ready = 1;
    return 0;
}

static void comp_reset(const instance* s, component* c, double t0) {
    c->role->reset(&c->comp, t0);
    c->n_queue = 0;
    c->head = 0;
    c->paired_now = 0;
    (void)s;
}

/* the outputs at the current sample for the inputs `in` (checked against their
 * ranges where they entered); what the step needs is kept in the component */
static int comp_evaluate(const instance* s, component* c, const double* in, double* out, lpv_msg* err) {
    const lpv_model* m = s->m;
    if (c->role->check && c->role->check(&c->comp, in, err)) return 1;
    if (c->delay == 0) return c->role->evaluate(&c->comp, in, out, err);
    c->paired_now = 0;
    if (c->n_queue < c->delay) { /* no measurement of a sample yet: every output 0 */
        for (int i = 0; i < m->n_outputs; i++) out[i] = 0.0;
        return 0;
    }
    const double* kept = c->queue + (size_t)c->head * (size_t)m->n_inputs;
    for (int p = 0; p < m->n_in_ports; p++) {
        const lpv_port* port = &m->in_ports[p];
        const double* src = port->late ? in : kept;
        for (int i = 0; i < port->size; i++) c->paired[port->offset + i] = src[port->offset + i];
    }
    if (c->role->evaluate(&c->comp, c->paired, out, err)) return 1;
    c->paired_now = 1;
    return 0;
}

static int comp_commit(const instance* s, component* c, const double* in, double t_end, lpv_msg* err) {
    const lpv_model* m = s->m;
    if (c->delay == 0) return c->role->commit(&c->comp, t_end, err);
    if (c->paired_now && c->role->commit(&c->comp, t_end, err)) return 1;
    c->paired_now = 0;
    int slot;
    if (c->n_queue == c->delay) { /* the oldest is consumed */
        slot = c->head;
        c->head = (c->head + 1) % c->delay;
    } else {
        slot = (c->head + c->n_queue) % c->delay;
        c->n_queue++;
    }
    memcpy(c->queue + (size_t)slot * (size_t)m->n_inputs, in, sizeof(double) * (size_t)m->n_inputs);
    return 0;
}


/* ----------------------------------------------------------- instance */

static char* dup_string(const char* text) {
    if (!text) text = "";
    size_t n = strlen(text) + 1;
    char* out = (char*)malloc(n);
    if (out) memcpy(out, text, n);
    return out;
}

static const char* NOT_INITIALIZED = "the FMU is not initialized yet (fmi2ExitInitializationMode)";

/* the start values and a fresh state (fmi2Instantiate, fmi2Reset) */
static int set_fresh(instance* s) {
    const lpv_model* m = s->m;
    for (int p = 0; p < m->n_params; p++) {
        const lpv_param* par = &m->params[p];
        if (par->type == LPV_REAL) {
            for (int i = 0; i < par->size; i++) s->reals[par->slot + i] = par->start_real[i];
        } else if (par->type == LPV_INTEGER) {
            s->ints[par->slot] = par->start_int;
        } else if (par->type == LPV_BOOLEAN) {
            s->bools[par->slot] = par->start_int != 0;
        } else {
            free(s->strings[par->slot]);
            s->strings[par->slot] = dup_string(par->start_string);
            if (!s->strings[par->slot]) return 1;
        }
    }
    /* each input starts at the point of its declared range nearest to 0 */
    for (int vr = 0; vr < m->n_vars; vr++) {
        const lpv_var* v = &m->vars[vr];
        if (v->kind != LPV_INPUT) continue;
        double lo = v->has_min ? v->min : -HUGE_VAL, hi = v->has_max ? v->max : HUGE_VAL;
        double x = 0.0 > lo ? 0.0 : lo;
        s->inputs[v->slot] = x < hi ? x : hi;
    }
    for (int i = 0; i < m->n_outputs; i++) s->outputs[i] = NAN, s->held[i] = 0.0;
    memset(s->reason, 0, (size_t)m->n_vars);
    s->n_invalid = 0;
    s->held_valid = 0;
    s->pending = 0;
    s->initialized = s->terminated = s->entered = 0;
    s->dirty = 1;
    s->n_nonfinite = 0;
    s->time = s->start_time = 0.0;
    s->stop_defined = 0;
    s->stop_time = 0.0;
    s->announced = 0;
    snprintf(s->init_error, sizeof s->init_error, "%s", NOT_INITIALIZED);
    comp_free(&s->comp);
    comp_free(&s->preview);
    s->preview_valid = 0;
    return 0;
}

static void instance_free(instance* s) {
    if (!s) return;
    comp_free(&s->comp);
    comp_free(&s->preview);
    if (s->strings)
        for (int i = 0; i < s->m->n_string; i++) free(s->strings[i]);
    free(s->strings);
    free(s->reals);
    free(s->ints);
    free(s->bools);
    free(s->inputs);
    free(s->outputs);
    free(s->held);
    free(s->scratch_out);
    free(s->invalid);
    free(s->reason);
    free(s->rejected_real);
    free(s->rejected_int);
    free(s->name);
    free(s);
}

/* ----------------------------------------------------- outputs on demand */

static int n_direct(const lpv_model* m) {
    int n = 0;
    for (int p = 0; p < m->n_out_ports; p++) n += m->out_ports[p].direct != 0;
    return n;
}

/* the outputs that hold after a step: the direct ones, when the component has inputs */
static int has_feedthrough(const lpv_model* m) { return m->n_in_ports > 0 && n_direct(m) > 0; }

static void count_nonfinite(instance* s) {
    s->n_nonfinite = 0;
    for (int i = 0; i < s->m->n_outputs; i++)
        if (!isfinite(s->outputs[i])) s->n_nonfinite++;
}

/* "output y[1], y[2] is not finite (NaN or inf)" for the values `out` */
static void nonfinite_text(const instance* s, const double* out, lpv_msg* into) {
    const lpv_model* m = s->m;
    int shown = 0, bad = 0;
    lpv_msgf(into, "output ");
    for (int vr = 0; vr < m->n_vars; vr++) {
        const lpv_var* v = &m->vars[vr];
        if (v->kind != LPV_OUTPUT || isfinite(out[v->slot])) continue;
        bad++;
        if (shown < 5) lpv_msg_append(into, "%s%s", shown ? ", " : "", v->name), shown++;
    }
    lpv_msg_append(into, "%s is not finite (NaN or inf)", bad > 5 ? " ..." : "");
}

static void nonfinite_problem(const instance* s, lpv_msg* into) {
    char t[48];
    nonfinite_text(s, s->outputs, into);
    lpv_msg_append(into, " at t = %s", lpv_num(t, s->time));
}

/* the component outputs are computed with: the configured one after
 * initialization, else one built from the current parameters */
static component* preview_component(instance* s, lpv_msg* err) {
    if (s->initialized) return &s->comp;
    if (!s->preview_valid) {
        if (comp_configure(s, &s->preview, err)) return NULL;
        comp_reset(s, &s->preview, s->start_time);
        s->preview_valid = 1;
    }
    return &s->preview;
}

/* compute the outputs when inputs, parameters or the state changed (_refresh) */
static int refresh(instance* s, lpv_msg* err) {
    const lpv_model* m = s->m;
    /* an input rejected since was not stored: the outputs follow the stored (valid) inputs */
    if (!s->dirty) return 0;
    component* c = preview_component(s, err);
    if (!c) return 1;
    if (!s->held_valid) {
        if (comp_evaluate(s, c, s->inputs, s->scratch_out, err)) return 1;
        memcpy(s->outputs, s->scratch_out, sizeof(double) * (size_t)m->n_outputs);
        s->pending = c == &s->comp;
    } else if (s->all_direct) {
        memcpy(s->outputs, s->held, sizeof(double) * (size_t)m->n_outputs);
    } else {
        /* outputs with no feedthrough at the new time; the others hold */
        if (comp_evaluate(s, c, s->inputs, s->scratch_out, err)) return 1;
        s->pending = 0;
        for (int p = 0; p < m->n_out_ports; p++) {
            const lpv_port* port = &m->out_ports[p];
            const double* src = port->direct ? s->held : s->scratch_out;
            memcpy(s->outputs + port->offset, src + port->offset, sizeof(double) * (size_t)port->size);
        }
    }
    s->dirty = 0;
    count_nonfinite(s);
    return 0;
}

/* ----------------------------------------------------------- invalid values */

static void invalid_remove(instance* s, int vr) {
    if (!s->reason[vr]) return;
    s->reason[vr] = REJECT_NONE;
    for (int i = 0; i < s->n_invalid; i++)
        if (s->invalid[i] == vr) {
            memmove(s->invalid + i, s->invalid + i + 1, sizeof(int) * (size_t)(s->n_invalid - i - 1));
            s->n_invalid--;
            break;
        }
}

/* the message a rejected value was logged with */
static void rejection_text(const instance* s, int vr, lpv_msg* into) {
    const lpv_var* v = &s->m->vars[vr];
    char a[48], lo[48], hi[48];
    if (s->reason[vr] == REJECT_NONFINITE) {
        lpv_msgf(into, "%s = %s is not finite; value rejected", v->what, lpv_repr(a, s->rejected_real[vr]));
    } else if (v->type == LPV_INTEGER) {
        lpv_msgf(into, "%s = %d is outside its declared range [", v->what, s->rejected_int[vr]);
        if (v->has_min) lpv_msg_append(into, "%.0f", v->min);
        else lpv_msg_append(into, "-inf");
        lpv_msg_append(into, ", ");
        if (v->has_max) lpv_msg_append(into, "%.0f", v->max);
        else lpv_msg_append(into, "inf");
        lpv_msg_append(into, "]; value rejected");
    } else {
        lpv_msgf(into, "%s = %s is outside its declared range [%s, %s]; value rejected", v->what,
                 lpv_num(a, s->rejected_real[vr]), v->has_min ? lpv_num(lo, v->min) : "-inf",
                 v->has_max ? lpv_num(hi, v->max) : "inf");
    }
}

static void reject(instance* s, int vr, int reason, double real_value, int int_value) {
    if (!s->reason[vr]) s->invalid[s->n_invalid++] = vr;
    s->reason[vr] = (unsigned char)reason;
    s->rejected_real[vr] = real_value;
    s->rejected_int[vr] = int_value;
    rejection_text(s, vr, &s->msg);
    logm(s, fmi2Error, s->msg.text);
}

/* a value arrives for variable vr (the Python slave's _set_element); returns 0 if stored */
static int arrive(instance* s, int vr) {
    const lpv_var* v = &s->m->vars[vr];
    if (s->terminated) {
        logf_(s, fmi2Error, "%s cannot be set after fmi2Terminate (reset the instance)", v->what);
        return 1;
    }
    if (v->kind == LPV_PARAMETER && s->initialized) {
        logf_(s, fmi2Error, "%s is fixed: it can be set only before fmi2ExitInitializationMode", v->what);
        return 1;
    }
    return 0;
}

static void stored(instance* s, int vr) {
    const lpv_var* v = &s->m->vars[vr];
    invalid_remove(s, vr);
    if (v->kind == LPV_PARAMETER) s->preview_valid = 0, comp_free(&s->preview);
    else s->held_valid = 0;
    s->dirty = 1;
    s->pending = 0;
}

static int check_vr(instance* s, const char* fn, const char* type_name, int type, fmi2ValueReference vr) {
    static const char* const type_names[] = {"Real", "Integer", "Boolean", "String"};
    if ((size_t)vr >= (size_t)s->m->n_vars) {
        logf_(s, fmi2Error, "%s: value reference %u is not a variable of this FMU", fn, (unsigned)vr);
        return 1;
    }
    const lpv_var* v = &s->m->vars[vr];
    if (v->type != type) { /* the Python slave's words (_not_of_type) */
        logf_(s, fmi2Error, "%s: value reference %u is the %s variable %s, not %s %s variable", fn, (unsigned)vr,
              type_names[v->type], v->name, type == LPV_INTEGER ? "an" : "a", type_name);
        return 1;
    }
    return 0;
}

/* ------------------------------------------------------------ FMI calls */

FMI2_Export const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
FMI2_Export const char* fmi2GetVersion(void) { return fmi2Version; }

FMI2_Export fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                          fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions,
                                          fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)visible;
    const lpv_model* m = &lpv_model_data;
    fmi2CallbackLogger logger = functions ? functions->logger : NULL;
    void* env = functions ? functions->componentEnvironment : NULL;
    const char* name = instanceName && lpv_is_utf8(instanceName) ? instanceName : "";
    if (!instanceName || !lpv_is_utf8(instanceName) || !lpv_has_text(instanceName)) { /* FMI 2.0: a name, in UTF-8 */
        if (logger)
            logger(env, name, fmi2Error, "logStatusError", "[%s] fmi2Instantiate: %s", m->identifier,
                   !instanceName                ? "no instance name (NULL)"
                   : !lpv_is_utf8(instanceName) ? "the instance name is not UTF-8 text"
                                                : LPV_BLANK_NAME);
        return NULL;
    }
    if (fmuType != fmi2CoSimulation) {
        if (logger) logger(env, name, fmi2Error, "logStatusError", "[%s] fmi2Instantiate: this FMU supports co-simulation only",
                           m->identifier);
        return NULL;
    }
    if (!fmuResourceLocation) { /* not read here, but refused as the Python FMUs refuse it */
        if (logger) logger(env, name, fmi2Error, "logStatusError", "[%s] fmi2Instantiate: " LPV_NO_RESOURCES, m->identifier);
        return NULL;
    }
    if (fmuGUID && strcmp(fmuGUID, m->guid) != 0) {
        if (logger)
            logger(env, name, fmi2Error, "logStatusError",
                   "[%s] " LPV_GUID_MISMATCH, m->identifier, fmuGUID, m->guid);
        return NULL;
    }
    if (m->n_model_params < 0 || m->n_model_params > LPV_MAX_MODEL_PARAMS) { /* not model data lpvest wrote */
        if (logger)
            logger(env, name, fmi2Error, "logStatusError",
                   "[%s] fmi2Instantiate: the model data holds %d model parameters; at most %d", m->identifier,
                   m->n_model_params, LPV_MAX_MODEL_PARAMS);
        return NULL;
    }
    instance* s = (instance*)calloc(1, sizeof(instance));
    if (!s) return NULL;
    s->m = m;
    if (functions) s->cb = *functions;
    s->name = dup_string(name);
    s->logging_on = loggingOn != 0;
    s->categories = (1u << N_CATEGORIES) - 1u;
    s->feedthrough = has_feedthrough(m);
    s->all_direct = n_direct(m) == m->n_out_ports;
    s->reals = (double*)zalloc((size_t)m->n_real, sizeof(double));
    s->ints = (int*)zalloc((size_t)m->n_int, sizeof(int));
    s->bools = (int*)zalloc((size_t)m->n_bool, sizeof(int));
    s->strings = (char**)zalloc((size_t)m->n_string, sizeof(char*));
    s->inputs = (double*)zalloc((size_t)m->n_inputs, sizeof(double));
    s->outputs = (double*)zalloc((size_t)m->n_outputs, sizeof(double));
    s->held = (double*)zalloc((size_t)m->n_outputs, sizeof(double));
    s->scratch_out = (double*)zalloc((size_t)m->n_outputs, sizeof(double));
    s->invalid = (int*)zalloc((size_t)m->n_vars, sizeof(int));
    s->reason = (unsigned char*)zalloc((size_t)m->n_vars, 1);
    s->rejected_real = (double*)zalloc((size_t)m->n_vars, sizeof(double));
    s->rejected_int = (int*)zalloc((size_t)m->n_vars, sizeof(int));
    if (!s->name || !s->reals || !s->ints || !s->bools || !s->strings || !s->inputs || !s->outputs || !s->held ||
        !s->scratch_out || !s->invalid || !s->reason || !s->rejected_real || !s->rejected_int || set_fresh(s)) {
        if (logger) logger(env, name, fmi2Error, "logStatusError", "[%s] fmi2Instantiate: out of memory", m->identifier);
        instance_free(s);
        return NULL;
    }
    return s;
}

FMI2_Export void fmi2FreeInstance(fmi2Component c) { instance_free((instance*)c); }

FMI2_Export fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                                           const fmi2String categories[]) {
    BEGIN(c);
    s->logging_on = loggingOn != 0;
    if (nCategories == 0) {
        s->categories = (1u << N_CATEGORIES) - 1u;
    } else {
        s->categories = 0;
        for (size_t i = 0; i < nCategories; i++) {
            int found = 0;
            for (int k = 0; k < N_CATEGORIES; k++)
                if (categories && categories[i] && strcmp(categories[i], CATEGORIES[k]) == 0)
                    s->categories |= 1u << k, found = 1;
            const char* name = categories ? categories[i] : NULL;
            if (!found)
                logf_(s, fmi2Warning, "fmi2SetDebugLogging: unknown log category %.200s",
                      !name ? "(null)" : lpv_is_utf8(name) ? name : "(not UTF-8 text)");
        }
    }
    END;
}

/* Why a call of the initialization (fmi2SetupExperiment, fmi2EnterInitializationMode: not after
 * fmi2EnterInitializationMode; fmi2ExitInitializationMode: once, after it) is out of its FMI state, or NULL;
 * the Python slave's words (_lifecycle_problem) */
static const char* lifecycle_problem(const instance* s, int entering) {
    if (s->terminated) return "the FMU is terminated (fmi2Terminate was called; reset or free the instance)";
    if (s->initialized)
        return "the FMU is initialized already (fmi2ExitInitializationMode was called; reset the instance to "
               "initialize it again)";
    if (entering && s->entered)
        return "the FMU is in initialization mode already (fmi2EnterInitializationMode was called)";
    if (!entering && !s->entered)
        return "the FMU is not in initialization mode (call fmi2EnterInitializationMode first)";
    return NULL;
}

/* whether the initialization call fn is out of its FMI state; if so the reason is logged at
 * fmi2Error (the Python slave's _refused_out_of_state) */
static int refused_out_of_state(instance* s, const char* fn, int entering) {
    const char* why = lifecycle_problem(s, entering);
    if (why) logf_(s, fmi2Error, "%s: %s", fn, why);
    return why != NULL;
}

FMI2_Export fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                                           fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    BEGIN(c);
    (void)toleranceDefined, (void)tolerance;
    if (!s->announced) logf_(s, fmi2OK, "lpvest %s (native runtime)", s->m->version);
    s->announced = 1;
    if (refused_out_of_state(s, "fmi2SetupExperiment", 1)) END;
    if (!isfinite(startTime)) {
        char a[48];
        logf_(s, fmi2Error, "fmi2SetupExperiment: ArgumentError: start time %s is not finite", lpv_repr(a, startTime));
        END;
    }
    if (stopTimeDefined && isnan(stopTime)) {
        logf_(s, fmi2Error, "fmi2SetupExperiment: ArgumentError: stop time nan is not a number");
        END;
    }
    if (stopTimeDefined && stopTime < startTime) {
        char a[48], b[48];
        logf_(s, fmi2Error, "fmi2SetupExperiment: ArgumentError: stop time %s is before the start time %s",
              lpv_repr(a, stopTime), lpv_repr(b, startTime));
        END;
    }
    s->stop_defined = stopTimeDefined != 0;
    s->stop_time = stopTime;
    s->start_time = s->time = startTime;
    s->preview_valid = 0;
    comp_free(&s->preview);
    s->dirty = 1;
    END;
}

FMI2_Export fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    BEGIN(c);
    if (!refused_out_of_state(s, "fmi2EnterInitializationMode", 1)) s->entered = 1;
    END;
}

FMI2_Export fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    BEGIN(c);
    if (refused_out_of_state(s, "fmi2ExitInitializationMode", 0)) END;
    const lpv_model* m = s->m;
    lpv_msg err;
    err.text[0] = '\0';
    int failed = 0;
    if (s->n_invalid) {
        lpv_msgf(&err, "invalid values were set: ");
        for (int i = 0; i < s->n_invalid; i++) {
            rejection_text(s, s->invalid[i], &s->msg);
            lpv_msg_append(&err, "%s%s", i ? "; " : "", s->msg.text);
        }
        failed = 1;
    } else if (m->sample_time >= 0 && !(s->reals[m->sample_time] > 0.0)) {
        char a[48];
        lpv_msgf(&err, "parameter sample_time = %s must be > 0", lpv_num(a, s->reals[m->sample_time]));
        failed = 1;
    } else if (comp_configure(s, &s->comp, &err)) {
        /* the Python slave logs the exception's text without its type here */
        char* colon = strstr(err.text, ": ");
        if (colon) memmove(err.text, colon + 2, strlen(colon + 2) + 1);
        failed = 1;
    }
    if (failed) {
        s->initialized = 0;
        comp_free(&s->comp);
        snprintf(s->init_error, sizeof s->init_error, "initialization failed: %s", err.text);
        logf_(s, fmi2Error, "fmi2ExitInitializationMode: %s", err.text);
        END;
    }
    comp_reset(s, &s->comp, s->start_time);
    s->time = s->start_time;
    s->initialized = 1;
    s->preview_valid = 0;
    comp_free(&s->preview);
    s->held_valid = 0;
    s->pending = 0;
    s->dirty = 1;
    END;
}

FMI2_Export fmi2Status fmi2Terminate(fmi2Component c) {
    BEGIN(c);
    s->terminated = 1;
    END;
}

FMI2_Export fmi2Status fmi2Reset(fmi2Component c) {
    BEGIN(c);
    if (set_fresh(s)) logf_(s, fmi2Error, "fmi2Reset: out of memory");
    END;
}

/* ------------------------------------------------------------------ get */

static int all_outputs(const instance* s, const fmi2ValueReference vr[], size_t nvr) {
    if (nvr == 0) return 0;
    for (size_t i = 0; i < nvr; i++)
        if ((size_t)vr[i] >= (size_t)s->m->n_vars || s->m->vars[vr[i]].kind != LPV_OUTPUT) return 0;
    return 1;
}

static void refresh_for_get(instance* s, const char* where) {
    lpv_msg err;
    if (refresh(s, &err)) logf_(s, fmi2Error, "%s (computing the outputs): %s", where, err.text);
    if (s->n_nonfinite) {
        nonfinite_problem(s, &err);
        logf_(s, fmi2Error, "%s: %s", where, err.text);
    }
}

FMI2_Export fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    BEGIN(c);
    REFUSE_NULL_ARRAYS("fmi2GetReal");
    if (all_outputs(s, vr, nvr)) {
        if (s->dirty) {
            lpv_msg err;
            if (refresh(s, &err)) logf_(s, fmi2Error, "fmi2GetReal (computing the outputs): %s", err.text);
        }
        if (s->n_nonfinite) {
            nonfinite_problem(s, &s->msg);
            logf_(s, fmi2Error, "fmi2GetReal: %s", s->msg.text);
        }
        for (size_t i = 0; i < nvr; i++) value[i] = s->outputs[s->m->vars[vr[i]].slot];
        END;
    }
    int outputs = 0;
    for (size_t i = 0; i < nvr; i++) {
        if (check_vr(s, "fmi2GetReal", "Real", LPV_REAL, vr[i])) {
            for (size_t k = 0; k < nvr; k++) value[k] = NAN;
            END;
        }
        outputs |= s->m->vars[vr[i]].kind == LPV_OUTPUT;
    }
    if (outputs) refresh_for_get(s, "fmi2GetReal");
    for (size_t i = 0; i < nvr; i++) {
        const lpv_var* v = &s->m->vars[vr[i]];
        value[i] = v->kind == LPV_PARAMETER ? s->reals[v->slot]
                   : v->kind == LPV_INPUT   ? s->inputs[v->slot]
                                            : s->outputs[v->slot];
    }
    END;
}

FMI2_Export fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      fmi2Integer value[]) {
    BEGIN(c);
    REFUSE_NULL_ARRAYS("fmi2GetInteger");
    for (size_t i = 0; i < nvr; i++)
        if (check_vr(s, "fmi2GetInteger", "Integer", LPV_INTEGER, vr[i])) {
            for (size_t k = 0; k < nvr; k++) value[k] = 0;
            END;
        }
    for (size_t i = 0; i < nvr; i++) value[i] = s->ints[s->m->vars[vr[i]].slot];
    END;
}

FMI2_Export fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      fmi2Boolean value[]) {
    BEGIN(c);
    REFUSE_NULL_ARRAYS("fmi2GetBoolean");
    for (size_t i = 0; i < nvr; i++)
        if (check_vr(s, "fmi2GetBoolean", "Boolean", LPV_BOOLEAN, vr[i])) {
            for (size_t k = 0; k < nvr; k++) value[k] = fmi2False;
            END;
        }
    for (size_t i = 0; i < nvr; i++) value[i] = s->bools[s->m->vars[vr[i]].slot] ? fmi2True : fmi2False;
    END;
}

FMI2_Export fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    BEGIN(c);
    REFUSE_NULL_ARRAYS("fmi2GetString");
    for (size_t i = 0; i < nvr; i++)
        if (check_vr(s, "fmi2GetString", "String", LPV_STRING, vr[i])) {
            for (size_t k = 0; k < nvr; k++) value[k] = "";
            END;
        }
    for (size_t i = 0; i < nvr; i++) value[i] = s->strings[s->m->vars[vr[i]].slot];
    END;
}

/* ------------------------------------------------------------------ set */

static int settable(instance* s, const char* fn, const char* type_name, int type, fmi2ValueReference vr) {
    if (check_vr(s, fn, type_name, type, vr)) return 0;
    if (s->m->vars[vr].kind == LPV_OUTPUT) {
        logf_(s, fmi2Error, "%s: %s is an output; it cannot be set", fn, s->m->vars[vr].name);
        return 0;
    }
    return 1;
}

FMI2_Export fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    BEGIN(c);
    REFUSE_NULL_ARRAYS("fmi2SetReal");
    for (size_t i = 0; i < nvr; i++) {
        if (!settable(s, "fmi2SetReal", "Real", LPV_REAL, vr[i]) || arrive(s, (int)vr[i])) continue;
        const lpv_var* v = &s->m->vars[vr[i]];
        double x = value[i];
        if (!isfinite(x)) {
            reject(s, (int)vr[i], REJECT_NONFINITE, x, 0);
            continue;
        }
        if ((v->has_min && x < v->min - v->tol) || (v->has_max && x > v->max + v->tol)) {
            reject(s, (int)vr[i], REJECT_RANGE, x, 0);
            continue;
        }
        if (v->kind == LPV_PARAMETER) s->reals[v->slot] = x;
        else s->inputs[v->slot] = x;
        stored(s, (int)vr[i]);
    }
    END;
}

FMI2_Export fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      const fmi2Integer value[]) {
    BEGIN(c);
    REFUSE_NULL_ARRAYS("fmi2SetInteger");
    for (size_t i = 0; i < nvr; i++) {
        if (!settable(s, "fmi2SetInteger", "Integer", LPV_INTEGER, vr[i]) || arrive(s, (int)vr[i])) continue;
        const lpv_var* v = &s->m->vars[vr[i]];
        int x = value[i];
        if ((v->has_min && x < v->min) || (v->has_max && x > v->max)) {
            reject(s, (int)vr[i], REJECT_RANGE, (double)x, x);
            continue;
        }
        s->ints[v->slot] = x;
        stored(s, (int)vr[i]);
    }
    END;
}

FMI2_Export fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                      const fmi2Boolean value[]) {
    BEGIN(c);
    REFUSE_NULL_ARRAYS("fmi2SetBoolean");
    for (size_t i = 0; i < nvr; i++) {
        if (!settable(s, "fmi2SetBoolean", "Boolean", LPV_BOOLEAN, vr[i]) || arrive(s, (int)vr[i])) continue;
        s->bools[s->m->vars[vr[i]].slot] = value[i] != fmi2False;
        stored(s, (int)vr[i]);
    }
    END;
}

FMI2_Export fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                     const fmi2String value[]) {
    BEGIN(c);
    REFUSE_NULL_ARRAYS("fmi2SetString");
    for (size_t i = 0; i < nvr; i++) { /* all or nothing, as the Python FMUs (status_bridge.c) */
        if (value[i] && lpv_is_utf8(value[i])) continue;
        logf_(s, fmi2Error, "fmi2SetString: value reference %u: the value is %s; no value set", vr[i],
              value[i] ? "not UTF-8 text" : "NULL");
        END;
    }
    /* the strings replaced are freed after the call's last element: a value may be one this FMU
       returned (fmi2GetString), which a host may pass back in the same call, for another element */
    char** replaced = (char**)calloc(nvr ? nvr : 1, sizeof(char*));
    if (!replaced) {
        logf_(s, fmi2Error, "fmi2SetString: out of memory");
        END;
    }
    for (size_t i = 0; i < nvr; i++) {
        if (!settable(s, "fmi2SetString", "String", LPV_STRING, vr[i]) || arrive(s, (int)vr[i])) continue;
        char* copy = dup_string(value[i]);
        if (!copy) {
            logf_(s, fmi2Error, "fmi2SetString: out of memory");
            continue;
        }
        int slot = s->m->vars[vr[i]].slot;
        replaced[i] = s->strings[slot];
        s->strings[slot] = copy;
        stored(s, (int)vr[i]);
    }
    for (size_t i = 0; i < nvr; i++) free(replaced[i]);
    free(replaced);
    END;
}

/* -------------------------------------------------------------- stepping */

/* how many samples the step h is (lpvest.protocol.whole_samples); 0: not whole */
static long samples_in(const instance* s, double h) {
    const lpv_model* m = s->m;
    if (m->sample_time < 0) return 1;
    /* one sample, the usual step: what the division below gives (a ratio of exactly 1), without it */
    if (h == s->reals[m->sample_time] && h > 0 && h <= DBL_MAX) return 1;
    double ratio = h / s->reals[m->sample_time];
    if (!isfinite(ratio) || !(ratio > 0.5) || TIME_RTOL * ratio >= 0.5) return 0;
    double r = floor(ratio + 0.5);
    if (ratio - floor(ratio) == 0.5) r = fmod(floor(ratio), 2.0) == 0.0 ? floor(ratio) : floor(ratio) + 1.0;
    double tol = TIME_RTOL * (ratio > 1.0 ? ratio : 1.0);
    if (!(fabs(ratio - r) <= tol)) return 0;
    return r > 2e9 ? 0 : (long)r;
}

/* why fmi2DoStep(t, h) is not a valid next step (_step_problem); 0: it is */
static int step_problem(instance* s, double t, double h, lpv_msg* p) {
    char a[48], b[48];
    if (s->terminated) {
        lpv_msgf(p, "the FMU is terminated (fmi2Terminate was called; reset or free the instance)");
        return 1;
    }
    if (!s->initialized) {
        lpv_msgf(p, "%s", s->init_error);
        return 1;
    }
    if (!(isfinite(t) && isfinite(h))) {
        lpv_msgf(p, "the communication point t = %s and step h = %s must be finite", lpv_num(a, t), lpv_num(b, h));
        return 1;
    }
    if (h <= 0) {
        lpv_msgf(p, "the communication step h = %s must be > 0", lpv_num(a, h));
        return 1;
    }
    double scale = fabs(t) > fabs(s->time) ? fabs(t) : fabs(s->time);
    if (h > scale) scale = h;
    double tol = TIME_RTOL * scale;
    /* far from 0 the fraction of |t| would exceed the step, or a sample of a longer step (skipped) */
    double unit = h;
    if (s->m->sample_time >= 0 && s->reals[s->m->sample_time] < unit) unit = s->reals[s->m->sample_time];
    if (tol > 0.5 * unit) tol = 0.5 * unit;
    if (fabs(t - s->time) > tol) {
        lpv_msgf(p,
                 "the communication point t = %s is not the FMU's current time %s (a skipped or repeated point; "
                 "restore a state with fmi2SetFMUstate to go back)",
                 lpv_num(a, t), lpv_num(b, s->time));
        return 1;
    }
    if (s->stop_defined) {
        double end = t + h, big = fabs(end) > fabs(s->stop_time) ? fabs(end) : fabs(s->stop_time);
        double slack = TIME_RTOL * (big > h ? big : h);
        if (slack > 0.5 * unit) slack = 0.5 * unit;
        if (end - s->stop_time > slack) {
            lpv_msgf(p, "the step would end at t + h = %s, after the stop time %s (fmi2SetupExperiment; FMI 2.0, 2.1.6)",
                     lpv_num(a, end), lpv_num(b, s->stop_time));
            return 1;
        }
    }
    if (s->m->sample_time >= 0 && samples_in(s, h) == 0) {
        double ts = s->reals[s->m->sample_time];
        if (TIME_RTOL * (h / ts) >= 0.5) { /* samples_in cannot tell m from m + 1 any more */
            char c[48];
            lpv_msgf(p,
                     "the communication step h = %s is %s samples of the sample time %s, more than one step runs "
                     "(fewer than 500000000 = 0.5 / 1e-9, the relative time tolerance; split it into shorter steps)",
                     lpv_num(a, h), lpv_num(b, h / ts), lpv_num(c, ts));
            return 1;
        }
        lpv_msgf(p,
                 "the communication step h = %s is not a whole number of samples of the sample time %s (a step "
                 "runs m >= 1 samples; set the parameter sample_time)",
                 lpv_num(a, h), lpv_num(b, s->reals[s->m->sample_time]));
        return 1;
    }
    if (s->n_invalid) {
        lpv_msgf(p, "invalid input(s) ");
        for (int i = 0; i < s->n_invalid; i++)
            lpv_msg_append(p, "%s%s", i ? ", " : "", s->m->vars[s->invalid[i]].name);
        lpv_msg_append(p, " (set valid values, restore a state with fmi2SetFMUstate, or reset)");
        return 1;
    }
    return 0;
}

static void save_comp(const instance* s, const component* c, double* st, uint64_t* words, double* t, int* nq,
                      int* head, double* queue) {
    memcpy(st, c->comp.st, sizeof(double) * c->comp.n_st);
    memcpy(words, c->comp.words, sizeof(uint64_t) * c->comp.n_words);
    *t = c->comp.t;
    *nq = c->n_queue;
    *head = c->head;
    if (c->delay) memcpy(queue, c->queue, sizeof(double) * (size_t)c->delay * (size_t)s->m->n_inputs);
}

static void load_comp(const instance* s, component* c, const double* st, const uint64_t* words, double t, int nq,
                      int head, const double* queue) {
    memcpy(c->comp.st, st, sizeof(double) * c->comp.n_st);
    memcpy(c->comp.words, words, sizeof(uint64_t) * c->comp.n_words);
    c->comp.t = t;
    c->n_queue = nq;
    c->head = head;
    if (c->delay) memcpy(c->queue, queue, sizeof(double) * (size_t)c->delay * (size_t)s->m->n_inputs);
}

FMI2_Export fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    BEGIN(c);
    (void)noSetFMUStatePriorToCurrentPoint;
    const lpv_model* m = s->m;
    char a[48], b[48], d[48];
    lpv_msg problem;
    int bad = step_problem(s, t, h, &problem);
    if (!bad) {
        if (s->held_valid) { /* no input was set since the last step: this sample has the same inputs */
            s->held_valid = 0;
            s->dirty = 1;
        }
        lpv_msg err;
        if (refresh(s, &err)) {
            logf_(s, fmi2Error, "fmi2DoStep at t = %s: %s", lpv_num(a, t), err.text);
            END;
        }
        if (s->n_nonfinite) {
            nonfinite_problem(s, &problem);
            bad = 1;
        }
    }
    if (bad) {
        logf_(s, fmi2Error, "fmi2DoStep refused at t = %s (h = %s): %s", lpv_num(a, t), lpv_num(b, h), problem.text);
        END;
    }
    component* k = &s->comp;
    long steps = samples_in(s, h);
    lpv_msg err;
    if (!s->pending && comp_evaluate(s, k, s->inputs, s->scratch_out, &err)) {
        logf_(s, fmi2Error, "fmi2DoStep at t = %s: %s", lpv_num(a, t), err.text);
        END;
    }
    double ts = m->sample_time >= 0 ? s->reals[m->sample_time] : h;
    /* a step of m samples consumes none of them when one fails: the state before it is kept */
    if (steps > 1) save_comp(s, k, k->backup_st, k->backup_words, &k->backup_t, &k->backup_nq, &k->backup_head,
                             k->backup_queue);
    if (comp_commit(s, k, s->inputs, steps > 1 ? t + ts : t + h, &err)) {
        logf_(s, fmi2Error, "fmi2DoStep at t = %s: %s", lpv_num(a, t), err.text);
        END;
    }
    s->pending = 0;
    const double* current = s->outputs;
    for (long i = 1; i < steps; i++) {
        const char* why = NULL;
        if (comp_evaluate(s, k, s->inputs, s->scratch_out, &err)) {
            why = err.text;
        } else {
            int nonfinite = 0;
            for (int j = 0; j < m->n_outputs; j++) nonfinite |= !isfinite(s->scratch_out[j]);
            if (nonfinite) {
                nonfinite_text(s, s->scratch_out, &problem);
                why = problem.text;
            }
        }
        if (!why && comp_commit(s, k, s->inputs, i == steps - 1 ? t + h : t + (double)(i + 1) * ts, &err))
            why = err.text;
        if (why) {
            load_comp(s, k, k->backup_st, k->backup_words, k->backup_t, k->backup_nq, k->backup_head,
                      k->backup_queue);
            logf_(s, fmi2Error,
                  "fmi2DoStep refused at t = %s (h = %s, %ld samples): sample %ld of %ld (at t = %s): %s; nothing "
                  "consumed",
                  lpv_num(a, t), lpv_num(b, h), steps, i + 1, steps, lpv_num(d, t + (double)i * ts), why);
            s->dirty = 1; /* the sample-k outputs are computed again (the same numbers) */
            END;
        }
        current = s->scratch_out;
    }
    s->time = t + h;
    if (s->feedthrough) {
        memcpy(s->held, current, sizeof(double) * (size_t)m->n_outputs);
        s->held_valid = 1;
    } else {
        s->held_valid = 0;
    }
    s->dirty = 1;
    END;
}

FMI2_Export fmi2Status fmi2CancelStep(fmi2Component c) {
    BEGIN(c);
    logf_(s, fmi2Error, "FMI function not supported: fmi2CancelStep");
    END;
}

/* a status this FMU does not have: fmi2Discard (FMI 2.0, 4.2.3) */
static fmi2Status not_available(instance* s, const char* what) {
    logf_(s, fmi2Discard, "%s: " LPV_STATUS_NOT_AVAILABLE, what);
    return fmi2Discard;
}

FMI2_Export fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind k, fmi2Status* value) {
    BEGIN(c);
    (void)k, (void)value;
    return not_available(s, "fmi2GetStatus");
}

FMI2_Export fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind k, fmi2Real* value) {
    BEGIN(c);
    if (!value) {
        logf_(s, fmi2Error, "fmi2GetRealStatus: a NULL argument (a state, pointer or buffer)");
        END;
    }
    if (k != fmi2LastSuccessfulTime) {
        return not_available(s, "fmi2GetRealStatus");
    }
    *value = s->time;
    END;
}

FMI2_Export fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind k, fmi2Integer* value) {
    BEGIN(c);
    (void)k, (void)value;
    return not_available(s, "fmi2GetIntegerStatus");
}

FMI2_Export fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind k, fmi2Boolean* value) {
    BEGIN(c);
    if (!value) {
        logf_(s, fmi2Error, "fmi2GetBooleanStatus: a NULL argument (a state, pointer or buffer)");
        END;
    }
    if (k != fmi2Terminated) {
        return not_available(s, "fmi2GetBooleanStatus");
    }
    *value = fmi2False;
    END;
}

FMI2_Export fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind k, fmi2String* value) {
    BEGIN(c);
    (void)k, (void)value;
    return not_available(s, "fmi2GetStringStatus");
}

FMI2_Export fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                                   const fmi2Integer order[], const fmi2Real value[]) {
    BEGIN(c);
    (void)vr, (void)nvr, (void)order, (void)value;
    logf_(s, fmi2Error, "FMI function not supported: fmi2SetRealInputDerivatives");
    END;
}

FMI2_Export fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                                    const fmi2Integer order[], fmi2Real value[]) {
    BEGIN(c);
    (void)vr, (void)nvr, (void)order, (void)value;
    logf_(s, fmi2Error, "FMI function not supported: fmi2GetRealOutputDerivatives");
    END;
}

FMI2_Export fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                                    size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                                    size_t nKnown, const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    BEGIN(c);
    (void)vUnknown_ref, (void)nUnknown, (void)vKnown_ref, (void)nKnown, (void)dvKnown, (void)dvUnknown;
    logf_(s, fmi2Error, "FMI function not supported: fmi2GetDirectionalDerivative");
    END;
}

/* ------------------------------------------------------------ FMU states */

/* An FMU state is its serialized form: the whole state of the instance (parameters,
 * inputs, outputs, what holds, invalid values, flags, time, the component's state). */
typedef struct {
    unsigned char* bytes;
    size_t size;
} state_blob;

typedef struct {
    unsigned char* p;
    size_t size, cap;
    int failed;
} writer;

static void put(writer* w, const void* data, size_t n) {
    if (w->failed) return;
    if (w->size + n > w->cap) {
        size_t cap = w->cap ? w->cap : 1024;
        while (cap < w->size + n) cap *= 2;
        unsigned char* q = (unsigned char*)realloc(w->p, cap);
        if (!q) {
            w->failed = 1;
            return;
        }
        w->p = q, w->cap = cap;
    }
    if (n) memcpy(w->p + w->size, data, n);
    w->size += n;
}
static void put_i32(writer* w, int32_t v) { put(w, &v, sizeof v); }
static void put_u64(writer* w, uint64_t v) { put(w, &v, sizeof v); }
static void put_f64(writer* w, double v) { put(w, &v, sizeof v); }
static void put_str(writer* w, const char* text) {
    size_t n = text ? strlen(text) : 0;
    put_u64(w, (uint64_t)n);
    put(w, text, n);
}

typedef struct {
    const unsigned char* p;
    size_t size, pos;
    int failed;
} reader;

static int get(reader* r, void* out, size_t n) {
    if (r->failed || n > r->size - r->pos) {
        r->failed = 1;
        if (out && n) memset(out, 0, n);
        return 1;
    }
    if (n) memcpy(out, r->p + r->pos, n);
    r->pos += n;
    return 0;
}
static int32_t get_i32(reader* r) {
    int32_t v = 0;
    get(r, &v, sizeof v);
    return v;
}
static uint64_t get_u64(reader* r) {
    uint64_t v = 0;
    get(r, &v, sizeof v);
    return v;
}
static double get_f64(reader* r) {
    double v = 0;
    get(r, &v, sizeof v);
    return v;
}
/* a string as a fresh allocation (NULL when malformed) */
static char* get_str(reader* r) {
    uint64_t n = get_u64(r);
    if (r->failed || n > r->size - r->pos) {
        r->failed = 1;
        return NULL;
    }
    char* out = (char*)malloc((size_t)n + 1);
    if (!out) {
        r->failed = 1;
        return NULL;
    }
    memcpy(out, r->p + r->pos, (size_t)n);
    out[n] = '\0';
    r->pos += (size_t)n;
    return out;
}

static const char STATE_MAGIC[8] = {'L', 'P', 'V', 'S', 'T', 'A', 'T', '2'};

/* FNV-1a (64 bits) of a state's bytes, stored after them: a buffer damaged since it was
 * serialized (a changed digit of an estimate, cut short) is refused, never restored */
static uint64_t checksum(const unsigned char* p, size_t n) {
    uint64_t h = 14695981039346656037ULL;
    for (size_t i = 0; i < n; i++) h = (h ^ p[i]) * 1099511628211ULL;
    return h;
}

static void serialize(const instance* s, writer* w) {
    const lpv_model* m = s->m;
    put(w, STATE_MAGIC, sizeof STATE_MAGIC);
    put_i32(w, 0x01020304);
    put_str(w, m->identifier);
    put_str(w, m->guid);
    put_i32(w, m->n_real), put_i32(w, m->n_int), put_i32(w, m->n_bool), put_i32(w, m->n_string);
    put_i32(w, m->n_inputs), put_i32(w, m->n_outputs), put_i32(w, m->n_vars);
    put(w, s->reals, sizeof(double) * (size_t)m->n_real);
    for (int i = 0; i < m->n_int; i++) put_i32(w, s->ints[i]);
    for (int i = 0; i < m->n_bool; i++) put_i32(w, s->bools[i]);
    for (int i = 0; i < m->n_string; i++) put_str(w, s->strings[i]);
    put(w, s->inputs, sizeof(double) * (size_t)m->n_inputs);
    put(w, s->outputs, sizeof(double) * (size_t)m->n_outputs);
    put(w, s->held, sizeof(double) * (size_t)m->n_outputs);
    put_i32(w, s->held_valid);
    put_i32(w, s->n_invalid);
    for (int i = 0; i < s->n_invalid; i++) {
        int vr = s->invalid[i];
        put_i32(w, vr), put_i32(w, s->reason[vr]), put_f64(w, s->rejected_real[vr]), put_i32(w, s->rejected_int[vr]);
    }
    put_i32(w, s->initialized), put_i32(w, s->terminated), put_i32(w, s->dirty);
    put_f64(w, s->time), put_f64(w, s->start_time);
    put_str(w, s->init_error);
    if (s->initialized) {
        const component* c = &s->comp;
        put_u64(w, c->comp.n_st);
        put(w, c->comp.st, sizeof(double) * c->comp.n_st);
        put_u64(w, c->comp.n_words);
        put(w, c->comp.words, sizeof(uint64_t) * c->comp.n_words);
        put_f64(w, c->comp.t);
        put_i32(w, c->delay), put_i32(w, c->n_queue), put_i32(w, c->head);
        put(w, c->queue, sizeof(double) * (size_t)c->delay * (size_t)m->n_inputs);
    }
    if (!w->failed) put_u64(w, checksum(w->p, w->size));
}

/* restore from bytes; the instance is changed only when everything checks out */
static int restore(instance* s, const unsigned char* bytes, size_t size, lpv_msg* err) {
    const lpv_model* m = s->m;
    reader r = {bytes, size, 0, 0};
    char magic[8];
    get(&r, magic, sizeof magic);
    if (r.failed || memcmp(magic, STATE_MAGIC, sizeof magic) != 0 || get_i32(&r) != 0x01020304) {
        lpv_msgf(err, "ArgumentError: not a serialized lpvest FMU state");
        return 1;
    }
    uint64_t stored = 0;
    if (size >= r.pos + sizeof stored) memcpy(&stored, bytes + size - sizeof stored, sizeof stored);
    if (size < r.pos + sizeof stored || stored != checksum(bytes, size - sizeof stored)) {
        lpv_msgf(err, "ArgumentError: not a serialized lpvest FMU state (it is damaged: its checksum does not match)");
        return 1;
    }
    r.size = size - sizeof stored; /* the checksum is not part of what is read */
    char* ident = get_str(&r);
    char* guid = get_str(&r);
    if (r.failed) {
        free(ident), free(guid);
        lpv_msgf(err, "ArgumentError: not a serialized lpvest FMU state (it is cut short or damaged)");
        return 1;
    }
    int same = ident && guid && strcmp(ident, m->identifier) == 0 && strcmp(guid, m->guid) == 0;
    if (!same) {
        lpv_msgf(err, "ArgumentError: the state belongs to '%s', not to '%s'%s", ident ? ident : "?", m->identifier,
                 ident && strcmp(ident, m->identifier) == 0 ? " (another build of it)" : "");
        free(ident), free(guid);
        return 1;
    }
    free(ident), free(guid);
    int counts[7] = {m->n_real, m->n_int, m->n_bool, m->n_string, m->n_inputs, m->n_outputs, m->n_vars};
    for (int i = 0; i < 7; i++)
        if (get_i32(&r) != counts[i]) {
            lpv_msgf(err, "ArgumentError: the state's parameters do not match this FMU");
            return 1;
        }
    /* into a scratch instance first */
    instance t;
    memset(&t, 0, sizeof t);
    t.m = m;
    int rc = 1;
    t.reals = (double*)zalloc((size_t)m->n_real, sizeof(double));
    t.ints = (int*)zalloc((size_t)m->n_int, sizeof(int));
    t.bools = (int*)zalloc((size_t)m->n_bool, sizeof(int));
    t.strings = (char**)zalloc((size_t)m->n_string, sizeof(char*));
    t.inputs = (double*)zalloc((size_t)m->n_inputs, sizeof(double));
    t.outputs = (double*)zalloc((size_t)m->n_outputs, sizeof(double));
    t.held = (double*)zalloc((size_t)m->n_outputs, sizeof(double));
    t.invalid = (int*)zalloc((size_t)m->n_vars, sizeof(int));
    t.reason = (unsigned char*)zalloc((size_t)m->n_vars, 1);
    t.rejected_real = (double*)zalloc((size_t)m->n_vars, sizeof(double));
    t.rejected_int = (int*)zalloc((size_t)m->n_vars, sizeof(int));
    if (!t.reals || !t.ints || !t.bools || !t.strings || !t.inputs || !t.outputs || !t.held || !t.invalid ||
        !t.reason || !t.rejected_real || !t.rejected_int) {
        lpv_msgf(err, "MemoryError: out of memory");
        goto done;
    }
    get(&r, t.reals, sizeof(double) * (size_t)m->n_real);
    for (int i = 0; i < m->n_int; i++) t.ints[i] = get_i32(&r);
    for (int i = 0; i < m->n_bool; i++) t.bools[i] = get_i32(&r) != 0;
    for (int i = 0; i < m->n_string; i++) t.strings[i] = get_str(&r);
    get(&r, t.inputs, sizeof(double) * (size_t)m->n_inputs);
    get(&r, t.outputs, sizeof(double) * (size_t)m->n_outputs);
    get(&r, t.held, sizeof(double) * (size_t)m->n_outputs);
    t.held_valid = get_i32(&r) != 0;
    t.n_invalid = get_i32(&r);
    if (t.n_invalid < 0 || t.n_invalid > m->n_vars) r.failed = 1;
    for (int i = 0; !r.failed && i < t.n_invalid; i++) {
        int vr = get_i32(&r), why = get_i32(&r);
        double x = get_f64(&r);
        int xi = get_i32(&r);
        if (vr < 0 || vr >= m->n_vars || m->vars[vr].kind == LPV_OUTPUT || why < 1 || why > 2 || t.reason[vr]) {
            r.failed = 1;
            break;
        }
        t.invalid[i] = vr, t.reason[vr] = (unsigned char)why, t.rejected_real[vr] = x, t.rejected_int[vr] = xi;
    }
    t.initialized = get_i32(&r) != 0;
    t.terminated = get_i32(&r) != 0;
    t.dirty = get_i32(&r) != 0;
    t.time = get_f64(&r);
    t.start_time = get_f64(&r);
    char* init_error = get_str(&r);
    if (init_error) snprintf(t.init_error, sizeof t.init_error, "%s", init_error);
    free(init_error);
    for (int i = 0; i < m->n_string; i++)
        if (!t.strings[i]) r.failed = 1;
    if (r.failed) {
        lpv_msgf(err, "ArgumentError: not a serialized lpvest FMU state (it is cut short or damaged)");
        goto done;
    }
    if (!isfinite(t.time) || !isfinite(t.start_time)) {
        lpv_msgf(err, "ArgumentError: the state's time (%.17g, started at %.17g) is not finite", t.time,
                 t.start_time);
        goto done;
    }
    if (t.initialized) {
        lpv_msg cfg_err;
        if (comp_configure(&t, &t.comp, &cfg_err)) {
            lpv_msgf(err, "%s", cfg_err.text);
            goto done;
        }
        component* c = &t.comp;
        uint64_t n_st = get_u64(&r);
        if (n_st != c->comp.n_st) r.failed = 1;
        else get(&r, c->comp.st, sizeof(double) * c->comp.n_st);
        uint64_t n_words = get_u64(&r);
        if (r.failed || n_words != c->comp.n_words) r.failed = 1;
        else get(&r, c->comp.words, sizeof(uint64_t) * c->comp.n_words);
        c->comp.t = get_f64(&r);
        int delay = get_i32(&r), nq = get_i32(&r), head = get_i32(&r);
        if (delay != c->delay || nq < 0 || nq > delay || head < 0 || (delay && head >= delay)) r.failed = 1;
        else get(&r, c->queue, sizeof(double) * (size_t)delay * (size_t)m->n_inputs);
        c->n_queue = nq, c->head = head;
        if (r.failed) {
            lpv_msgf(err, "ArgumentError: the state's component does not fit this FMU's parameters");
            goto done;
        }
        const lpv_role* role = role_of(m);
        if (role->check_state && role->check_state(&c->comp, err)) goto done;
    }
    if (r.pos != r.size) {
        lpv_msgf(err, "ArgumentError: not a serialized lpvest FMU state (%lu bytes too many)",
                 (unsigned long)(r.size - r.pos));
        goto done;
    }
    /* everything checked out: swap it in */
    {
        instance keep = *s;
        s->reals = t.reals, s->ints = t.ints, s->bools = t.bools, s->strings = t.strings;
        s->inputs = t.inputs, s->outputs = t.outputs, s->held = t.held, s->held_valid = t.held_valid;
        s->invalid = t.invalid, s->n_invalid = t.n_invalid, s->reason = t.reason;
        s->rejected_real = t.rejected_real, s->rejected_int = t.rejected_int;
        s->initialized = t.initialized, s->terminated = t.terminated, s->dirty = t.dirty;
        s->time = t.time, s->start_time = t.start_time;
        memcpy(s->init_error, t.init_error, sizeof s->init_error);
        s->comp = t.comp;
        s->pending = 0;
        /* outputs to compute again are checked then; the restored ones (not dirty) now: a step
           refused for an output that is not finite stays refused after a restore */
        if (s->dirty) s->n_nonfinite = 0;
        else count_nonfinite(s);
        s->preview_valid = 0;
        /* the old arrays go with the scratch instance */
        t.reals = keep.reals, t.ints = keep.ints, t.bools = keep.bools, t.strings = keep.strings;
        t.inputs = keep.inputs, t.outputs = keep.outputs, t.held = keep.held, t.invalid = keep.invalid;
        t.reason = keep.reason, t.rejected_real = keep.rejected_real, t.rejected_int = keep.rejected_int;
        t.comp = keep.comp;
        comp_free(&s->preview);
        rc = 0;
    }
done:
    comp_free(&t.comp);
    if (t.strings)
        for (int i = 0; i < m->n_string; i++) free(t.strings[i]);
    free(t.strings), free(t.reals), free(t.ints), free(t.bools), free(t.inputs), free(t.outputs), free(t.held);
    free(t.invalid), free(t.reason), free(t.rejected_real), free(t.rejected_int);
    return rc;
}

FMI2_Export fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* state) {
    BEGIN(c);
    if (!state) {
        logf_(s, fmi2Error, "fmi2GetFMUstate: " LPV_NULL_ARGUMENT);
        END;
    }
    writer w = {NULL, 0, 0, 0};
    serialize(s, &w);
    state_blob* blob = (state_blob*)*state;
    if (w.failed || (!blob && !(blob = (state_blob*)calloc(1, sizeof(state_blob))))) {
        free(w.p);
        logf_(s, fmi2Error, "fmi2GetFMUstate: out of memory");
        END;
    }
    free(blob->bytes);
    blob->bytes = w.p;
    blob->size = w.size;
    *state = blob;
    END;
}

FMI2_Export fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    BEGIN(c);
    const state_blob* blob = (const state_blob*)state;
    lpv_msg err;
    if (!blob || !blob->bytes) lpv_msgf(&err, LPV_NULL_ARGUMENT);
    if (!blob || !blob->bytes || restore(s, blob->bytes, blob->size, &err)) logf_(s, fmi2Error, "fmi2SetFMUstate: %s", err.text);
    END;
}

FMI2_Export fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* state) {
    BEGIN(c);
    if (state && *state) {
        state_blob* blob = (state_blob*)*state;
        free(blob->bytes);
        free(blob);
        *state = NULL;
    }
    END;
}

FMI2_Export fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t* size) {
    BEGIN(c);
    const state_blob* blob = (const state_blob*)state;
    if (!blob || !size) {
        logf_(s, fmi2Error, "fmi2SerializedFMUstateSize: " LPV_NULL_ARGUMENT);
        END;
    }
    *size = blob->size;
    END;
}

FMI2_Export fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte serializedState[],
                                             size_t size) {
    BEGIN(c);
    const state_blob* blob = (const state_blob*)state;
    if (!blob || !serializedState) {
        logf_(s, fmi2Error, "fmi2SerializeFMUstate: " LPV_NULL_ARGUMENT);
        END;
    }
    if (size < blob->size) {
        logf_(s, fmi2Error, "fmi2SerializeFMUstate: " LPV_BUFFER_TOO_SMALL, (unsigned long long)size,
              (unsigned long long)blob->size);
        END;
    }
    memcpy(serializedState, blob->bytes, blob->size);
    END;
}

FMI2_Export fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                               fmi2FMUstate* state) {
    BEGIN(c);
    if (!serializedState || !state) {
        logf_(s, fmi2Error, "fmi2DeSerializeFMUstate: " LPV_NULL_ARGUMENT);
        END;
    }
    /* checked when set (fmi2SetFMUstate); here: the header */
    if (size < sizeof STATE_MAGIC || memcmp(serializedState, STATE_MAGIC, sizeof STATE_MAGIC) != 0) {
        logf_(s, fmi2Error, "fmi2DeSerializeFMUstate: " LPV_NOT_A_STATE);
        END;
    }
    state_blob* blob = (state_blob*)calloc(1, sizeof(state_blob));
    unsigned char* bytes = (unsigned char*)malloc(size);
    if (!blob || !bytes) {
        free(blob), free(bytes);
        logf_(s, fmi2Error, "fmi2DeSerializeFMUstate: out of memory");
        END;
    }
    memcpy(bytes, serializedState, size);
    blob->bytes = bytes;
    blob->size = size;
    /* *state is an output only (FMI 2.0, 2.1.8: "constructs a copy of the FMU state and
       returns FMUstate"): what it held on entry is the host's, not freed here (a host may
       still free it, or it may be uninitialized), as pythonfmu does */
    *state = blob;
    END;
}
