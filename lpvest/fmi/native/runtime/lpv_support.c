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

/* ------------------------------------------------- Python's repr, abbreviated */

/* the code points Python's str.isprintable() refuses, above ASCII, but for the unassigned ones:
   categories Cc, Zs, Zl, Zp, Cf and Co of Unicode 14.0 (Python 3.11) and 15.0 (3.12: U+13439 to
   U+1343F became Cf; unassigned before, which Python escapes too). tests/test_native_core.py
   checks it against the running Python's unicodedata. */
static const unsigned long NOT_PRINTABLE[][2] = {
    {0x80, 0xa0},       {0xad, 0xad},       {0x600, 0x605},     {0x61c, 0x61c},     {0x6dd, 0x6dd},
    {0x70f, 0x70f},     {0x890, 0x891},     {0x8e2, 0x8e2},     {0x1680, 0x1680},   {0x180e, 0x180e},
    {0x2000, 0x200f},   {0x2028, 0x202f},   {0x205f, 0x2064},   {0x2066, 0x206f},   {0x3000, 0x3000},
    {0xe000, 0xf8ff},   {0xfeff, 0xfeff},   {0xfff9, 0xfffb},   {0x110bd, 0x110bd}, {0x110cd, 0x110cd},
    {0x13430, 0x1343f}, {0x1bca0, 0x1bca3}, {0x1d173, 0x1d17a}, {0xe0001, 0xe0001}, {0xe0020, 0xe007f},
    {0xf0000, 0xffffd}, {0x100000, 0x10fffd}};

static int printable(unsigned long cp) {
    if (cp < 0x20 || cp == 0x7f) return 0;
    for (size_t i = 0; cp >= 0x80 && i < sizeof NOT_PRINTABLE / sizeof NOT_PRINTABLE[0]; i++)
        if (cp >= NOT_PRINTABLE[i][0] && cp <= NOT_PRINTABLE[i][1]) return 0;
    return 1;
}

/* how repr shows cp inside quotes q (0: as a string of this one character, where no quote is
   escaped), into out (at least 11 bytes); its length in characters in *width; returns the bytes */
static size_t shown(unsigned long cp, char q, char* out, size_t* width) {
    size_t n;
    if (cp == '\\' || (q && cp == (unsigned long)q)) out[0] = '\\', out[1] = (char)cp, n = 2;
    else if (cp == '\t') memcpy(out, "\\t", 2), n = 2;
    else if (cp == '\n') memcpy(out, "\\n", 2), n = 2;
    else if (cp == '\r') memcpy(out, "\\r", 2), n = 2;
    else if (!printable(cp))
        n = (size_t)snprintf(out, 11, cp < 0x100 ? "\\x%02lx" : cp < 0x10000 ? "\\u%04lx" : "\\U%08lx", cp);
    else {
        *width = 1;
        if (cp < 0x80) return out[0] = (char)cp, 1;
        if (cp < 0x800) return out[0] = (char)(0xC0 | (cp >> 6)), out[1] = (char)(0x80 | (cp & 0x3F)), 2;
        if (cp < 0x10000)
            return out[0] = (char)(0xE0 | (cp >> 12)), out[1] = (char)(0x80 | ((cp >> 6) & 0x3F)),
                   out[2] = (char)(0x80 | (cp & 0x3F)), 3;
        return out[0] = (char)(0xF0 | (cp >> 18)), out[1] = (char)(0x80 | ((cp >> 12) & 0x3F)),
               out[2] = (char)(0x80 | ((cp >> 6) & 0x3F)), out[3] = (char)(0x80 | (cp & 0x3F)), 4;
    }
    *width = n;
    return n;
}

/* repr of the code points cps[0..n) into out; its length in characters */
static size_t repr_of(const unsigned long* cps, size_t n, char* out, size_t size) {
    int single = 0, dbl = 0;
    for (size_t i = 0; i < n; i++) single |= cps[i] == '\'', dbl |= cps[i] == '"';
    char q = single && !dbl ? '"' : '\'';
    size_t pos = 0, chars = 2;
    if (size) out[pos++] = q;
    for (size_t i = 0; i < n; i++) {
        char one[12];
        size_t width, bytes = shown(cps[i], q, one, &width);
        chars += width;
        for (size_t k = 0; k < bytes && pos + 2 < size; k++) out[pos++] = one[k];
    }
    if (pos + 1 < size) out[pos++] = q;
    if (size) out[pos < size ? pos : size - 1] = '\0';
    return chars;
}

void lpv_abbreviate(char* out, size_t size, const char* text, size_t len, int limit) {
    unsigned long* cps = (unsigned long*)malloc((len + 3) * sizeof(unsigned long));
    if (!cps) {
        snprintf(out, size, "(a text of %lu bytes)", (unsigned long)len);
        return;
    }
    size_t n = 0;
    const unsigned char* p = (const unsigned char*)text;
    for (size_t i = 0; i < len; n++) { /* valid UTF-8 (the FMI setters refuse other text); a stray byte as itself */
        unsigned c = p[i];
        int more = c < 0x80 ? 0 : (c & 0xE0) == 0xC0 ? 1 : (c & 0xF0) == 0xE0 ? 2 : (c & 0xF8) == 0xF0 ? 3 : 0;
        if (i + (size_t)more >= len) more = 0;
        unsigned long cp = more == 0 ? c : more == 1 ? (c & 0x1F) : more == 2 ? (c & 0x0F) : (c & 0x07);
        for (int k = 1; k <= more; k++) cp = (cp << 6) | (p[i + (size_t)k] & 0x3F);
        cps[n] = cp;
        i += 1 + (size_t)more;
    }
    if (repr_of(cps, n, out, size) <= (size_t)limit) {
        free(cps);
        return;
    }
    /* the start and the end, each by the width its characters are shown in (abbreviate) */
    size_t keep = (size_t)(limit - 10 > 8 ? limit - 10 : 8), used = 0, head = n, tail = n;
    char one[12];
    for (size_t i = 0, w; i < n; i++) {
        shown(cps[i], 0, one, &w);
        if ((used += w) > keep * 3 / 4) {
            head = i;
            break;
        }
    }
    if (head == 0 && n) head = 1; /* the first character at least (as abbreviate) */
    used = 0;
    for (size_t i = n, w; i > head; i--) {
        shown(cps[i - 1], 0, one, &w);
        if ((used += w) > keep / 4) break;
        tail = i - 1;
    }
    /* head, "...", tail: the tail moved first (head + 3 + n - tail <= n + 3 code points fit) */
    memmove(cps + head + 3, cps + tail, (n - tail) * sizeof(unsigned long));
    size_t m = head;
    for (int k = 0; k < 3; k++) cps[m++] = '.';
    char joined[320];
    repr_of(cps, m + (n - tail), joined, sizeof joined);
    char digits[32], grouped[48];
    int nd = snprintf(digits, sizeof digits, "%lu", (unsigned long)n), g = 0;
    for (int i = 0; i < nd; i++) {
        if (i && (nd - i) % 3 == 0) grouped[g++] = ',';
        grouped[g++] = digits[i];
    }
    grouped[g] = '\0';
    snprintf(out, size, "%s (%s characters)", joined, grouped);
    free(cps);
}
