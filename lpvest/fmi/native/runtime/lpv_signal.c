/*
 * lpvest native runtime: the Scheduler and Source roles (lpvest.signals).
 *
 * A signal of one kind per output port (the Scheduler: p, and alpha = map(p) of a
 * polytopic model; the Source: u and/or w), a function of the communication
 * point's time: any step. Kinds, per component j at time t:
 *   zero      0
 *   constant  offset
 *   sinusoid  offset + amplitude sin(omega t + phase)
 *   decaying  offset + amplitude sin(omega t + phase) exp(-decay t)
 *   gaussian  offset + std z, z a fresh standard normal of the signal's stream
 *   random    s <- clip(s + rate h (-1 + 2 u), lower, upper), from offset
 *   table     piecewise linear through the rows (t_i, v_i) (numpy.interp)
 * Before `onset` every kind but table holds offset (zero: 0). The parameters are
 * checked as lpvest.signals.SignalSpec.build and SchedulerComponent check them,
 * with the same messages.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "lpv.h"

enum { K_ZERO = 0, K_CONSTANT, K_SINUSOID, K_DECAYING, K_GAUSSIAN, K_RANDOM, K_TABLE, K_COUNT };
static const char* const KINDS[K_COUNT] = {"zero", "constant", "sinusoid", "decaying", "gaussian", "random", "table"};

/* one signal's configuration in cfg: kind, n, seed, onset, then per component
 * amplitude, omega, phase, offset, decay, std, rate, lower, upper; then the table
 * (m rows: t, v_1..v_n) */
enum { F_AMPLITUDE = 0, F_OMEGA, F_PHASE, F_OFFSET, F_DECAY, F_STD, F_RATE, F_LOWER, F_UPPER, F_COUNT };
#define HEAD 5 /* kind, n, seed, onset, table rows */

typedef struct {
    int n_signals;
    const lpv_signal_def* defs;
    int scheduler;
    const lpv_scheduler_data* sd;
} signals;

static signals signals_of(const lpv_model* m) {
    signals s;
    memset(&s, 0, sizeof s);
    if (m->role == LPV_ROLE_SCHEDULER) {
        s.scheduler = 1;
        s.sd = (const lpv_scheduler_data*)m->data;
        s.n_signals = 1;
    } else {
        const lpv_source_data* d = (const lpv_source_data*)m->data;
        s.n_signals = d->n_signals;
        s.defs = d->signals;
    }
    return s;
}

static int sig_n(const signals* s, int i) { return s->scheduler ? s->sd->n_p : s->defs[i].n; }
static const char* sig_prefix(const signals* s, int i) { return s->scheduler ? "" : s->defs[i].prefix; }
static int sig_out(const signals* s, int i) { return s->scheduler ? s->sd->out_p : s->defs[i].out; }

/* ------------------------------------------------------------ the table */

static int is_space(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v' || c == '\n'; }


/* parse_table: rows 't v_1 ... v_n' into out (rows x (n + 1)); returns the rows, or -1 with err */
static int parse_table(const char* text, int n, const char* name, double* out, lpv_msg* err) {
    int rows = 0;
    const char* p = text ? text : "";
    while (*p) {
        const char* e = p;
        while (*e && *e != ';' && *e != '\n') e++;
        const char* a = p;
        const char* z = e;
        while (a < z && is_space(*a)) a++;
        while (z > a && is_space(z[-1])) z--;
        if (a < z) {
            /* fields split at runs of ',' and blanks */
            int fields = 0, number_ok = 1;
            const char* f = a;
            while (f < z) {
                while (f < z && (*f == ',' || is_space(*f))) f++;
                if (f >= z) break;
                const char* g = f;
                while (g < z && *g != ',' && !is_space(*g)) g++;
                double x;
                if (!lpv_parse_float(f, (size_t)(g - f), &x)) number_ok = 0;
                else if (fields < n + 1 && out) out[(size_t)rows * (size_t)(n + 1) + (size_t)fields] = x;
                fields++;
                f = g;
            }
            char shown[320];
            lpv_abbreviate(shown, sizeof shown, a, (size_t)(z - a), 30);
            if (fields != n + 1) {
                lpv_msgf(err, "SignalError: %s row %d (%s) has %d numbers; expected %d (t and %d values)", name, rows + 1,
                         shown, fields, n + 1, n);
                return -1;
            }
            if (!number_ok) {
                lpv_msgf(err, "SignalError: %s row %d (%s) holds something that is not a number", name, rows + 1, shown);
                return -1;
            }
            rows++;
        }
        p = *e ? e + 1 : e;
    }
    if (rows == 0) {
        lpv_msgf(err, "SignalError: %s is empty; expected rows 't v_1 ... v_%d' separated by ';'", name, n);
        return -1;
    }
    if (out) {
        for (int i = 0; i < rows * (n + 1); i++)
            if (!isfinite(out[i])) {
                lpv_msgf(err, "SignalError: %s holds a non-finite number", name);
                return -1;
            }
        for (int i = 1; i < rows; i++)
            if (!(out[(size_t)i * (size_t)(n + 1)] > out[(size_t)(i - 1) * (size_t)(n + 1)])) {
                lpv_msgf(err, "SignalError: %s: the times (first column) must be strictly increasing; found [", name);
                for (int k = 0; k < rows; k++) {
                    char a[48];
                    lpv_msg_append(err, "%s%s", k ? ", " : "", lpv_repr(a, out[(size_t)k * (size_t)(n + 1)]));
                }
                lpv_msg_append(err, "]");
                return -1;
            }
    }
    return rows;
}

/* numpy.interp(t, times, values[:, j]) for a table of `rows` rows */
static double interp(double t, const double* table, int rows, int n, int j) {
    const int w = n + 1;
    const double* x = table;
    if (rows == 1) return table[1 + j];
    if (isnan(t)) return t;
    if (t > x[(size_t)(rows - 1) * w]) return table[(size_t)(rows - 1) * w + 1 + j];
    if (t < x[0]) return table[1 + j];
    int lo = 0, hi = rows; /* the last k with x[k] <= t */
    while (hi - lo > 1) {
        int mid = (lo + hi) / 2;
        if (x[(size_t)mid * w] <= t) lo = mid;
        else hi = mid;
    }
    int k = lo;
    if (k == rows - 1) return table[(size_t)k * w + 1 + j];
    double xk = x[(size_t)k * w], yk = table[(size_t)k * w + 1 + j];
    double xk1 = x[(size_t)(k + 1) * w], yk1 = table[(size_t)(k + 1) * w + 1 + j];
    if (t == xk) return yk;
    double slope = (yk1 - yk) / (xk1 - xk);
    double r = slope * (t - xk) + yk;
    if (isnan(r)) {
        r = slope * (t - xk1) + yk1;
        if (isnan(r) && yk == yk1) r = yk;
    }
    return r;
}

/* ------------------------------------------------------------ the role */

/* the configuration of signal i in cfg, and its size */
static size_t sig_cfg_size(int n, int rows) { return HEAD + (size_t)F_COUNT * (size_t)n + (size_t)rows * (size_t)(n + 1); }

static int read_signal(const lpv_model* m, const lpv_values* v, const signals* s, int i, double* cfg, int* rows_out,
                       lpv_msg* err) {
    const char* prefix = sig_prefix(s, i);
    int n = sig_n(s, i);
    char key[64];
#define KEY(k) (snprintf(key, sizeof key, "%s%s", prefix, (k)), key)
    const char* kind_text = lpv_param_string(m, v, KEY("kind"));
    int kind = -1;
    for (int k = 0; k < K_COUNT; k++)
        if (kind_text && strcmp(kind_text, KINDS[k]) == 0) kind = k;
    if (kind < 0) {
        char shown[320];
        lpv_abbreviate(shown, sizeof shown, kind_text ? kind_text : "", kind_text ? strlen(kind_text) : 0, 30);
        lpv_msgf(err, "SignalError: %skind = %s is not a signal kind (one of zero, constant, sinusoid, decaying, gaussian, "
                 "random, table)", prefix, shown);
        return 1;
    }
    static const char* const FIELDS[F_COUNT] = {"amplitude", "omega", "phase", "offset", "decay", "std", "rate",
                                                "lower", "upper"};
    static const double DEFAULTS[F_COUNT] = {1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, -HUGE_VAL, HUGE_VAL};
    for (int f = 0; f < F_COUNT; f++) {
        const double* values = f < F_LOWER ? lpv_param_reals(m, v, KEY(FIELDS[f])) : NULL;
        for (int j = 0; j < n; j++) {
            double x = values ? values[j] : DEFAULTS[f];
            if (s->scheduler && f == F_LOWER) x = s->sd->lower[j];
            if (s->scheduler && f == F_UPPER) x = s->sd->upper[j];
            if (cfg) cfg[HEAD + (size_t)f * (size_t)n + (size_t)j] = x;
        }
    }
    /* the checks of SignalSpec.build, in its order */
    for (int j = 0; cfg && j < n; j++) {
        double lo = cfg[HEAD + F_LOWER * n + j], hi = cfg[HEAD + F_UPPER * n + j];
        if (!(lo <= hi)) {
            char a[48], b[48];
            lpv_msgf(err, "SignalError: %slower[%d] = %s exceeds %supper[%d] = %s", prefix, j + 1, lpv_fmt_g(a, lo, 6), prefix,
                     j + 1, lpv_fmt_g(b, hi, 6));
            return 1;
        }
    }
    double onset = 0.0;
    const double* onset_p = lpv_param_reals(m, v, KEY("onset"));
    if (onset_p) onset = onset_p[0];
    int seed = lpv_param_int(m, v, KEY("seed"), 0);
    int rows = 0;
    if (kind == K_TABLE) {
        const char* table = lpv_param_string(m, v, KEY("table"));
        char name[64];
        snprintf(name, sizeof name, "%stable", prefix);
        rows = parse_table(table, n, name, cfg ? cfg + HEAD + (size_t)F_COUNT * (size_t)n : NULL, err);
        if (rows < 0) return 1;
    }
    for (int f = F_STD; cfg && f <= F_RATE; f++)
        for (int j = 0; j < n; j++) {
            double x = cfg[HEAD + (size_t)f * (size_t)n + (size_t)j];
            if (x < 0) {
                char a[48];
                lpv_msgf(err, "SignalError: %s%s[%d] = %s must be >= 0", prefix, FIELDS[f], j + 1, lpv_fmt_g(a, x, 6));
                return 1;
            }
        }
    if (cfg) {
        cfg[0] = kind, cfg[1] = n, cfg[2] = seed, cfg[3] = onset, cfg[4] = rows;
    }
    *rows_out = rows;
#undef KEY
    return 0;
}

/* the interval every value of signal i lies in (SignalSpec.bounds) */
static void bounds(const double* cfg, int j, double* lo, double* hi) {
    int kind = (int)cfg[0], n = (int)cfg[1];
    double onset = cfg[3];
    const double* F = cfg + HEAD;
    double off = F[F_OFFSET * n + j];
    if (kind == K_ZERO) *lo = *hi = 0.0;
    else if (kind == K_CONSTANT) *lo = *hi = off;
    else if (kind == K_SINUSOID || kind == K_DECAYING) {
        double a = fabs(F[F_AMPLITUDE * n + j]);
        if (kind == K_DECAYING) {
            double decay = F[F_DECAY * n + j];
            double scale = decay >= 0 ? exp(-decay * onset) : HUGE_VAL;
            a = a == 0 ? 0.0 : a * scale;
        }
        *lo = off < off - a ? off : off - a;
        *hi = off > off + a ? off : off + a;
    } else if (kind == K_GAUSSIAN) {
        double inf = F[F_STD * n + j] > 0 ? HUGE_VAL : 0.0;
        *lo = off - inf, *hi = off + inf;
    } else if (kind == K_RANDOM) {
        double lower = F[F_LOWER * n + j], upper = F[F_UPPER * n + j];
        double start = off < lower ? lower : off > upper ? upper : off;
        int moving = F[F_RATE * n + j] > 0;
        *lo = moving ? lower : start, *hi = moving ? upper : start;
    } else {
        int rows = (int)cfg[4];
        const double* table = F + F_COUNT * n;
        *lo = *hi = table[1 + j];
        for (int r = 1; r < rows; r++) {
            double x = table[(size_t)r * (size_t)(n + 1) + 1 + (size_t)j];
            if (x < *lo) *lo = x;
            if (x > *hi) *hi = x;
        }
    }
}

/* cfg: per signal its block; st: per signal its value (n); words: 4 per signal; tmp: map work */
static int sizes(const lpv_model* m, const lpv_values* v, const double* mp, lpv_sizes* out, lpv_msg* err) {
    (void)mp;
    signals s = signals_of(m);
    size_t cfg = 0, st = 0;
    for (int i = 0; i < s.n_signals; i++) {
        int rows = 0;
        if (read_signal(m, v, &s, i, NULL, &rows, err)) return 1;
        cfg += sig_cfg_size(sig_n(&s, i), rows);
        st += (size_t)sig_n(&s, i);
    }
    out->n_cfg = cfg;
    out->n_st = st;
    out->n_words = 4 * (size_t)s.n_signals;
    out->n_tmp = s.scheduler ? (size_t)(s.sd->map.n_formulas + s.sd->map.n_out + s.sd->n_p + 1) : 1;
    return 0;
}

static double* sig_cfg(lpv_comp* c, const signals* s, int i) {
    double* p = c->cfg;
    for (int k = 0; k < i; k++) p += sig_cfg_size((int)p[1], (int)p[4]);
    (void)s;
    return p;
}

static int configure(lpv_comp* c, const lpv_values* v, const double* mp, lpv_msg* err) {
    (void)mp;
    const lpv_model* m = c->model;
    signals s = signals_of(m);
    double* p = c->cfg;
    for (int i = 0; i < s.n_signals; i++) {
        int rows = 0;
        if (read_signal(m, v, &s, i, p, &rows, err)) return 1;
        p += sig_cfg_size(sig_n(&s, i), rows);
    }
    if (s.scheduler) { /* SchedulerComponent: the signal must stay inside the scheduling box */
        const lpv_scheduler_data* sd = s.sd;
        double* cfg = c->cfg;
        int kind = (int)cfg[0], n = sd->n_p;
        const double* F = cfg + HEAD;
        for (int j = 0; j < n; j++) {
            double lo, hi;
            bounds(cfg, j, &lo, &hi);
            double L = sd->lower[j], U = sd->upper[j];
            double big = fabs(L) > fabs(U) ? fabs(L) : fabs(U);
            double tol = 1e-12 * (big > 1.0 ? big : 1.0);
            if (lo >= L - tol && hi <= U + tol) continue;
            char a[48], b[48], e1[48], e2[48];
            if (kind == K_SINUSOID || kind == K_DECAYING)
                lpv_msgf(err, "SignalError: amplitude[%d] = %s with offset[%d] = %s", j + 1, lpv_fmt_g(a, F[F_AMPLITUDE * n + j], 6),
                         j + 1, lpv_fmt_g(b, F[F_OFFSET * n + j], 6));
            else if (kind == K_CONSTANT)
                lpv_msgf(err, "SignalError: offset[%d] = %s", j + 1, lpv_fmt_g(a, F[F_OFFSET * n + j], 6));
            else if (kind == K_TABLE)
                lpv_msgf(err, "SignalError: table (column %d)", j + 1);
            else
                lpv_msgf(err, "SignalError: kind = '%s' (std[%d] = %s)", KINDS[kind], j + 1, lpv_fmt_g(a, F[F_STD * n + j], 6));
            lpv_msg_append(err, " takes p[%d] (%s) to [%s, %s], outside its declared range [", j + 1, sd->names[j],
                           lpv_fmt_g(e1, lo, 6), lpv_fmt_g(e2, hi, 6));
            lpv_msg_append(err, "%s, ", lpv_fmt_g(a, L, 6));
            lpv_msg_append(err, "%s]", lpv_fmt_g(a, U, 6));
            return 1;
        }
    }
    return 0;
}

/* the value of a deterministic kind at time t (SignalSpec.deterministic_value) */
static void deterministic(const double* cfg, double t, double* out) {
    int kind = (int)cfg[0], n = (int)cfg[1];
    double onset = cfg[3];
    const double* F = cfg + HEAD;
    for (int j = 0; j < n; j++) {
        if (kind == K_TABLE) out[j] = interp(t, F + F_COUNT * n, (int)cfg[4], n, j);
        else if (kind == K_ZERO) out[j] = 0.0;
        else if (t < onset || kind == K_CONSTANT) out[j] = F[F_OFFSET * n + j];
        else {
            double s = F[F_AMPLITUDE * n + j] * sin(F[F_OMEGA * n + j] * t + F[F_PHASE * n + j]);
            if (kind == K_DECAYING) s = s * exp(-F[F_DECAY * n + j] * t);
            out[j] = F[F_OFFSET * n + j] + s;
        }
    }
}

static void gaussian(const double* cfg, double t, lpv_pcg64* g, double* out) {
    int n = (int)cfg[1];
    const double* F = cfg + HEAD;
    if (t < cfg[3]) {
        for (int j = 0; j < n; j++) out[j] = F[F_OFFSET * n + j];
        return;
    }
    for (int j = 0; j < n; j++) {
        double z = lpv_normal(g);
        out[j] = F[F_OFFSET * n + j] + F[F_STD * n + j] * z;
    }
}

static void reset(lpv_comp* c, double t0) {
    signals s = signals_of(c->model);
    c->t = t0;
    double* value = c->st;
    for (int i = 0; i < s.n_signals; i++) {
        double* cfg = sig_cfg(c, &s, i);
        int kind = (int)cfg[0], n = (int)cfg[1];
        const double* F = cfg + HEAD;
        lpv_pcg64* g = (lpv_pcg64*)(c->words + 4 * (size_t)i);
        uint32_t word = (uint32_t)(int)cfg[2];
        lpv_pcg64_seed(g, &word, 1);
        if (kind == K_RANDOM) {
            for (int j = 0; j < n; j++) {
                double x = F[F_OFFSET * n + j], lo = F[F_LOWER * n + j], hi = F[F_UPPER * n + j];
                value[j] = x < lo ? lo : x > hi ? hi : x;
            }
        } else if (kind == K_GAUSSIAN) {
            gaussian(cfg, t0, g, value);
        } else {
            deterministic(cfg, t0, value);
        }
        value += n;
    }
}

static int evaluate(lpv_comp* c, const double* in, double* out, lpv_msg* err) {
    (void)in, (void)err;
    const lpv_model* m = c->model;
    signals s = signals_of(m);
    const double* value = c->st;
    for (int i = 0; i < s.n_signals; i++) {
        int n = sig_n(&s, i);
        double* o = out + sig_out(&s, i);
        if (s.scheduler) { /* p = clip(value, lower, upper) */
            for (int j = 0; j < n; j++) {
                double x = value[j], lo = s.sd->lower[j], hi = s.sd->upper[j];
                o[j] = x < lo ? lo : x > hi ? hi : x;
            }
            if (s.sd->map.kind != LPV_MAP_NONE) lpv_map_eval(&s.sd->map, o, out + s.sd->out_alpha, c->tmp);
        } else {
            memcpy(o, value, sizeof(double) * (size_t)n);
        }
        value += n;
    }
    return 0;
}

static int commit(lpv_comp* c, double t_end, lpv_msg* err) {
    (void)err;
    signals s = signals_of(c->model);
    double h = t_end - c->t;
    double* value = c->st;
    for (int i = 0; i < s.n_signals; i++) {
        double* cfg = sig_cfg(c, &s, i);
        int kind = (int)cfg[0], n = (int)cfg[1];
        const double* F = cfg + HEAD;
        lpv_pcg64* g = (lpv_pcg64*)(c->words + 4 * (size_t)i);
        if (kind == K_RANDOM) {
            if (t_end >= cfg[3])
                for (int j = 0; j < n; j++) {
                    double u = lpv_uniform(g);
                    double step = F[F_RATE * n + j] * h * (-1.0 + 2.0 * u);
                    double x = value[j] + step, lo = F[F_LOWER * n + j], hi = F[F_UPPER * n + j];
                    value[j] = x < lo ? lo : x > hi ? hi : x;
                }
        } else if (kind == K_GAUSSIAN) {
            gaussian(cfg, t_end, g, value);
        } else {
            deterministic(cfg, t_end, value);
        }
        value += n;
    }
    c->t = t_end;
    return 0;
}

static const lpv_role SCHEDULER = {sizes, configure, reset, NULL, evaluate, commit, NULL};
static const lpv_role SOURCE = {sizes, configure, reset, NULL, evaluate, commit, NULL};

const lpv_role* lpv_role_scheduler(void) { return &SCHEDULER; }
const lpv_role* lpv_role_source(void) { return &SOURCE; }
