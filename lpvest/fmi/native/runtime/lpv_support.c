/*
 * lpvest native runtime: messages, numbers written as Python writes them, and
 * the parameter lookups the roles use.
 *
 * The messages of a native FMU are those of the Python FMU of the same role
 * (lpvest/fmi/_slave.py and the components it runs), numbers included: Python's
 * repr of a float (the shortest text that reads back exactly), format(v, "g").
 * The C library's printf gives the digits; the layout is built here, so a host's
 * locale (a decimal comma) or its C library's exponent width changes nothing.
 */
#include <locale.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "lpv.h"

void lpv_msgf(lpv_msg* m, const char* fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(m->text, sizeof m->text, fmt, ap);
    va_end(ap);
}

void lpv_msg_append(lpv_msg* m, const char* fmt, ...) {
    size_t n = strlen(m->text);
    if (n + 1 >= sizeof m->text) return;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(m->text + n, sizeof m->text - n, fmt, ap);
    va_end(ap);
}

/* ------------------------------------------------------------- numbers */

/* The decimal digits (without point, no trailing zeros) and the decimal exponent of
 * v rounded to `prec` significant digits: v ~ 0.d1d2d3... x 10^(exp + 1), i.e.
 * d1.d2d3... x 10^exp. v finite and nonzero. */
static void digits_of(double v, int prec, char* digits, int* exp10) {
    char tmp[64];
    snprintf(tmp, sizeof tmp, "%.*e", prec - 1, fabs(v));
    int n = 0;
    const char* p = tmp;
    for (; *p && *p != 'e' && *p != 'E'; p++)
        if (*p >= '0' && *p <= '9') digits[n++] = *p;
    digits[n] = '\0';
    *exp10 = *p ? atoi(p + 1) : 0;
    while (n > 1 && digits[n - 1] == '0') digits[--n] = '\0';
}

/* Whether the `prec`-digit rounding of v reads back as v. */
static int reads_back(double v, int prec) {
    char tmp[64];
    snprintf(tmp, sizeof tmp, "%.*e", prec - 1, v);
    return strtod(tmp, NULL) == v; /* printf and strtod share the locale */
}

static char* special(char* buf, double v) {
    if (isnan(v)) strcpy(buf, "nan");
    else strcpy(buf, v > 0 ? "inf" : "-inf");
    return buf;
}

/* digits d (n of them) with decimal exponent e in fixed notation (Python's layout) */
static void fixed(char* out, const char* d, int e, int min_frac) {
    int n = (int)strlen(d), pos = 0;
    if (e < 0) {
        out[pos++] = '0';
        out[pos++] = '.';
        for (int i = 0; i < -e - 1; i++) out[pos++] = '0';
        for (int i = 0; i < n; i++) out[pos++] = d[i];
    } else {
        for (int i = 0; i <= e; i++) out[pos++] = i < n ? d[i] : '0';
        if (n > e + 1) {
            out[pos++] = '.';
            for (int i = e + 1; i < n; i++) out[pos++] = d[i];
        } else if (min_frac) {
            out[pos++] = '.';
            out[pos++] = '0';
        }
    }
    out[pos] = '\0';
}

static void scientific(char* out, const char* d, int e) {
    int n = (int)strlen(d), pos = 0;
    out[pos++] = d[0];
    if (n > 1) {
        out[pos++] = '.';
        for (int i = 1; i < n; i++) out[pos++] = d[i];
    }
    sprintf(out + pos, "e%c%02d", e < 0 ? '-' : '+', e < 0 ? -e : e);
}

char* lpv_repr(char* buf, double v) {
    if (!isfinite(v)) return special(buf, v);
    if (v == 0.0) {
        strcpy(buf, signbit(v) ? "-0.0" : "0.0");
        return buf;
    }
    int prec = 1;
    while (prec < 17 && !reads_back(v, prec)) prec++;
    char d[40];
    int e;
    digits_of(v, prec, d, &e);
    char* out = buf;
    if (v < 0) *out++ = '-';
    if (e >= -4 && e < 16) fixed(out, d, e, 1);
    else scientific(out, d, e);
    return buf;
}

char* lpv_num(char* buf, double v) {
    lpv_repr(buf, v);
    size_t n = strlen(buf);
    if (n > 2 && strcmp(buf + n - 2, ".0") == 0) buf[n - 2] = '\0';
    return buf;
}

char* lpv_fmt_g(char* buf, double v, int prec) {
    if (!isfinite(v)) return special(buf, v);
    if (prec < 1) prec = 1;
    if (v == 0.0) {
        strcpy(buf, signbit(v) ? "-0" : "0");
        return buf;
    }
    char d[40];
    int e;
    digits_of(v, prec, d, &e);
    char* out = buf;
    if (v < 0) *out++ = '-';
    if (e >= -4 && e < prec) fixed(out, d, e, 0);
    else scientific(out, d, e);
    return buf;
}

char* lpv_repr_list(char* buf, size_t size, const double* v, int n) {
    size_t pos = 0;
    if (size < 3) {
        if (size) buf[0] = '\0';
        return buf;
    }
    buf[pos++] = '[';
    for (int i = 0; i < n; i++) {
        char one[48];
        lpv_repr(one, v[i]);
        size_t len = strlen(one) + (i ? 2 : 0);
        if (pos + len + 2 > size) break;
        if (i) buf[pos++] = ',', buf[pos++] = ' ';
        memcpy(buf + pos, one, strlen(one));
        pos += strlen(one);
    }
    buf[pos++] = ']';
    buf[pos] = '\0';
    return buf;
}

static int is_digit(char c) { return c >= '0' && c <= '9'; }

int lpv_parse_float(const char* s, size_t len, double* out) {
    while (len && (*s == ' ' || *s == '\t' || *s == '\n' || *s == '\r' || *s == '\f' || *s == '\v')) s++, len--;
    while (len && (s[len - 1] == ' ' || s[len - 1] == '\t' || s[len - 1] == '\n' || s[len - 1] == '\r' ||
                   s[len - 1] == '\f' || s[len - 1] == '\v'))
        len--;
    if (len == 0 || len > 300) return 0;
    char clean[320];
    size_t i = 0, n = 0;
    int neg = 0;
    if (s[i] == '+' || s[i] == '-') neg = s[i] == '-', clean[n++] = s[i++];
    /* inf, infinity, nan (any case) */
    const char* rest = s + i;
    size_t rl = len - i;
    if ((rl == 3 || rl == 8) && (rest[0] == 'i' || rest[0] == 'I')) {
        const char* word = "infinity";
        for (size_t k = 0; k < rl; k++)
            if ((rest[k] | 0x20) != word[k]) return 0;
        *out = neg ? -HUGE_VAL : HUGE_VAL;
        return 1;
    }
    if (rl == 3 && (rest[0] | 0x20) == 'n' && (rest[1] | 0x20) == 'a' && (rest[2] | 0x20) == 'n') {
        *out = neg ? -NAN : NAN;
        return 1;
    }
    /* digits [. digits] [e [sign] digits], an underscore only between two digits */
    int seen_digit = 0, seen_point = 0, seen_exp = 0, exp_digit = 0;
    const char* point = localeconv()->decimal_point;
    for (; i < len; i++) {
        char c = s[i];
        if (is_digit(c)) {
            clean[n++] = c;
            if (seen_exp) exp_digit = 1;
            else seen_digit = 1;
        } else if (c == '_') {
            if (!(i > 0 && is_digit(s[i - 1]) && i + 1 < len && is_digit(s[i + 1]))) return 0;
        } else if (c == '.' && !seen_point && !seen_exp) {
            seen_point = 1;
            for (const char* q = point; *q; q++) clean[n++] = *q;
        } else if ((c == 'e' || c == 'E') && seen_digit && !seen_exp) {
            seen_exp = 1;
            clean[n++] = 'e';
            if (i + 1 < len && (s[i + 1] == '+' || s[i + 1] == '-')) clean[n++] = s[++i];
        } else {
            return 0;
        }
        if (n > 300) return 0;
    }
    if (!seen_digit || (seen_exp && !exp_digit)) return 0;
    clean[n] = '\0';
    *out = strtod(clean, NULL);
    return 1;
}

/* ---------------------------------------------------------- parameters */

int lpv_param_index(const lpv_model* m, const char* name) {
    for (int i = 0; i < m->n_params; i++)
        if (strcmp(m->params[i].name, name) == 0) return i;
    return -1;
}

const double* lpv_param_reals(const lpv_model* m, const lpv_values* v, const char* name) {
    int i = lpv_param_index(m, name);
    return i >= 0 && m->params[i].type == LPV_REAL ? v->reals + m->params[i].slot : NULL;
}

int lpv_param_int(const lpv_model* m, const lpv_values* v, const char* name, int fallback) {
    int i = lpv_param_index(m, name);
    return i >= 0 && m->params[i].type == LPV_INTEGER ? v->ints[m->params[i].slot] : fallback;
}

int lpv_param_bool(const lpv_model* m, const lpv_values* v, const char* name, int fallback) {
    int i = lpv_param_index(m, name);
    return i >= 0 && m->params[i].type == LPV_BOOLEAN ? v->bools[m->params[i].slot] : fallback;
}

const char* lpv_param_string(const lpv_model* m, const lpv_values* v, const char* name) {
    int i = lpv_param_index(m, name);
    return i >= 0 && m->params[i].type == LPV_STRING ? v->strings[m->params[i].slot] : NULL;
}

void lpv_apply_entries(const lpv_model* m, int array, const double* model_params, double* target) {
    for (int i = 0; i < m->n_entries; i++)
        if (m->entries[i].array == array)
            target[m->entries[i].index] = lpv_formula_eval(&m->entries[i].f, model_params);
}
