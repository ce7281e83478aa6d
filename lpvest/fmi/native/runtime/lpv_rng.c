/*
 * lpvest native runtime: the random generator of lpvest/core/_rng.py, bit for bit.
 *
 * Raw words: PCG64 (O'Neill's XSL-RR output of a 128-bit LCG, the bit generator
 * numpy.random.PCG64 implements), seeded as numpy seeds it: SeedSequence's hash of
 * the entropy into a pool of four 32-bit words, eight words generated from the
 * pool, the first two 64-bit words the initial state and the last two the stream
 * (increment). The 128-bit arithmetic is written with 64-bit halves, so every C99
 * compiler builds it (MSVC has no 128-bit integer type).
 *
 * Normals: AS 241 (Wichura 1988, PPND16) at u = ((w >> 12) + 1/2) 2^-52, with the
 * logarithm of fdlibm's e_log.c computed from + - * / sqrt and the exact frexp.
 * These operations are correctly rounded in IEEE arithmetic, so compiled without
 * contraction (-ffp-contract=off) this gives lpvest.rng's numbers on every platform.
 */
#include <math.h>

#include "lpv_core.h"

/* ------------------------------------------------------------- 128-bit */

typedef struct {
    uint64_t hi, lo;
} u128;

static u128 mul64(uint64_t a, uint64_t b) { /* the full 128-bit product */
    uint64_t a0 = a & 0xffffffffu, a1 = a >> 32, b0 = b & 0xffffffffu, b1 = b >> 32;
    uint64_t p00 = a0 * b0, p01 = a0 * b1, p10 = a1 * b0, p11 = a1 * b1;
    uint64_t mid = (p00 >> 32) + (p01 & 0xffffffffu) + (p10 & 0xffffffffu);
    u128 r;
    r.lo = (mid << 32) | (p00 & 0xffffffffu);
    r.hi = p11 + (p01 >> 32) + (p10 >> 32) + (mid >> 32);
    return r;
}

static u128 mul128(u128 a, u128 b) { /* a b mod 2^128 */
    u128 r = mul64(a.lo, b.lo);
    r.hi += a.hi * b.lo + a.lo * b.hi;
    return r;
}

static u128 add128(u128 a, u128 b) {
    u128 r;
    r.lo = a.lo + b.lo;
    r.hi = a.hi + b.hi + (r.lo < a.lo);
    return r;
}

/* PCG_DEFAULT_MULTIPLIER_128 */
static const u128 PCG_MULT = {0x2360ED051FC65DA4ULL, 0x4385DF649FCCF645ULL};

static void pcg_step(lpv_pcg64* g) {
    u128 s = {g->state_hi, g->state_lo}, inc = {g->inc_hi, g->inc_lo};
    s = add128(mul128(s, PCG_MULT), inc);
    g->state_hi = s.hi;
    g->state_lo = s.lo;
}

uint64_t lpv_pcg64_next(lpv_pcg64* g) {
    pcg_step(g);
    uint64_t x = g->state_hi ^ g->state_lo;
    unsigned rot = (unsigned)(g->state_hi >> 58);
    return (x >> rot) | (x << ((64u - rot) & 63u));
}

/* ------------------------------------------------------- SeedSequence */

#define SS_INIT_A 0x43b0d7e5u
#define SS_MULT_A 0x931e8875u
#define SS_INIT_B 0x8b51f9ddu
#define SS_MULT_B 0x58f38dedu
#define SS_MIX_L 0xca01f9ddu
#define SS_MIX_R 0x4973f715u
#define SS_XSHIFT 16
#define SS_POOL 4

static uint32_t hashmix(uint32_t value, uint32_t* hash_const) {
    value ^= *hash_const;
    *hash_const *= SS_MULT_A;
    value *= *hash_const;
    value ^= value >> SS_XSHIFT;
    return value;
}

static uint32_t mix(uint32_t x, uint32_t y) {
    uint32_t r = SS_MIX_L * x - SS_MIX_R * y;
    r ^= r >> SS_XSHIFT;
    return r;
}

void lpv_pcg64_seed(lpv_pcg64* g, const uint32_t* words, int n) {
    uint32_t zero = 0;
    if (n <= 0) words = &zero, n = 1; /* the integer 0 is the one word 0 */
    uint32_t pool[SS_POOL], hash_const = SS_INIT_A;
    for (int i = 0; i < SS_POOL; i++) pool[i] = hashmix(i < n ? words[i] : 0u, &hash_const);
    for (int src = 0; src < SS_POOL; src++)
        for (int dst = 0; dst < SS_POOL; dst++)
            if (src != dst) pool[dst] = mix(pool[dst], hashmix(pool[src], &hash_const));
    for (int src = SS_POOL; src < n; src++)
        for (int dst = 0; dst < SS_POOL; dst++) pool[dst] = mix(pool[dst], hashmix(words[src], &hash_const));
    uint32_t out[8];
    uint32_t hb = SS_INIT_B;
    for (int i = 0; i < 8; i++) {
        uint32_t v = pool[i % SS_POOL];
        v ^= hb;
        hb *= SS_MULT_B;
        v *= hb;
        v ^= v >> SS_XSHIFT;
        out[i] = v;
    }
    uint64_t w[4];
    for (int i = 0; i < 4; i++) w[i] = (uint64_t)out[2 * i] | ((uint64_t)out[2 * i + 1] << 32);
    /* pcg_setseq_128_srandom_r(state = w[0]:w[1], seq = w[2]:w[3]) */
    u128 initstate = {w[0], w[1]}, initseq = {w[2], w[3]};
    g->inc_hi = (initseq.hi << 1) | (initseq.lo >> 63);
    g->inc_lo = (initseq.lo << 1) | 1u;
    g->state_hi = g->state_lo = 0;
    pcg_step(g);
    u128 s = add128((u128){g->state_hi, g->state_lo}, initstate);
    g->state_hi = s.hi;
    g->state_lo = s.lo;
    pcg_step(g);
}

/* ------------------------------------------------------------- doubles */

double lpv_uniform(lpv_pcg64* g) { return (double)(lpv_pcg64_next(g) >> 11) * 0x1.0p-53; }

/* fdlibm e_log.c (Sun Microsystems, 1993): ln 2 in two parts, the minimax R */
static const double LN2_HI = 6.93147180369123816490e-01, LN2_LO = 1.90821492927058770002e-10,
                    LG1 = 6.666666666666735130e-01, LG2 = 3.999999999940941908e-01, LG3 = 2.857142874366239149e-01,
                    LG4 = 2.222219843214978396e-01, LG5 = 1.818357216161805012e-01, LG6 = 1.531383769920937332e-01,
                    LG7 = 1.479819860511658591e-01, SQRT2 = 1.4142135623730951;

double lpv_log(double x) {
    int e;
    double m = frexp(x, &e); /* x = m 2^e, m in [1/2, 1) */
    double m2 = m * 2.0;
    double k = (double)(e - 1);
    if (m2 > SQRT2) m2 = m, k = k + 1.0;
    double f = m2 - 1.0;
    double s = f / (2.0 + f);
    double z = s * s;
    double w = z * z;
    double t1 = w * (LG2 + w * (LG4 + w * LG6));
    double t2 = z * (LG1 + w * (LG3 + w * (LG5 + w * LG7)));
    double r = t2 + t1;
    double hfsq = 0.5 * f * f;
    return k * LN2_HI - ((hfsq - (s * (hfsq + r) + k * LN2_LO)) - f);
}

static double horner(const double* c, double r) {
    double acc = c[0] * r + c[1];
    for (int i = 2; i < 8; i++) acc = acc * r + c[i];
    return acc;
}

/* AS 241 (PPND16), highest power first */
static const double AS_A[8] = {2.5090809287301226727e+3, 3.3430575583588128105e+4, 6.7265770927008700853e+4,
                               4.5921953931549871457e+4, 1.3731693765509461125e+4, 1.9715909503065514427e+3,
                               1.3314166789178437745e+2, 3.3871328727963666080e+0};
static const double AS_B[8] = {5.2264952788528545610e+3, 2.8729085735721942674e+4, 3.9307895800092710610e+4,
                               2.1213794301586595867e+4, 5.3941960214247511077e+3, 6.8718700749205790830e+2,
                               4.2313330701600911252e+1, 1.0};
static const double AS_C[8] = {7.74545014278341407640e-4, 2.27238449892691845833e-2, 2.41780725177450611770e-1,
                               1.27045825245236838258e+0, 3.64784832476320460504e+0, 5.76949722146069140550e+0,
                               4.63033784615654529590e+0, 1.42343711074968357734e+0};
static const double AS_D[8] = {1.05075007164441684324e-9, 5.47593808499534494600e-4, 1.51986665636164571966e-2,
                               1.48103976427480074590e-1, 6.89767334985100004550e-1, 1.67638483018380384940e+0,
                               2.05319162663775882187e+0, 1.0};
static const double AS_E[8] = {2.01033439929228813265e-7, 2.71155556874348757815e-5, 1.24266094738807843860e-3,
                               2.65321895265761230930e-2, 2.96560571828504891230e-1, 1.78482653991729133580e+0,
                               5.46378491116411436990e+0, 6.65790464350110377720e+0};
static const double AS_F[8] = {2.04426310338993978564e-15, 1.42151175831644588870e-7, 1.84631831751005468180e-5,
                               7.86869131145613259100e-4, 1.48753612908506148525e-2, 1.36929880922735805310e-1,
                               5.99832206555887937690e-1, 1.0};

double lpv_normal_quantile(double p) {
    double q = p - 0.5;
    if (fabs(q) <= 0.425) {
        double r = 0.180625 - q * q;
        return (horner(AS_A, r) * q) / horner(AS_B, r);
    }
    double r = q <= 0.0 ? p : 1.0 - p;
    r = sqrt(-lpv_log(r));
    double x;
    if (r <= 5.0) {
        double r1 = r - 1.6;
        x = horner(AS_C, r1) / horner(AS_D, r1);
    } else {
        double r2 = r - 5.0;
        x = horner(AS_E, r2) / horner(AS_F, r2);
    }
    return q < 0.0 ? -x : x;
}

double lpv_normal(lpv_pcg64* g) {
    double u = ((double)(lpv_pcg64_next(g) >> 12) + 0.5) * 0x1.0p-52;
    return lpv_normal_quantile(u);
}
