/*
 * lpvest native runtime: the numerical core (dense kernels, the random
 * generator, the formula virtual machine). C99, no allocation, no global state.
 *
 * Every function here is pure: it reads its arguments and writes its outputs.
 * Matrices are row-major arrays of doubles; dimensions are ints (the runtime's
 * models are small: n <= a few dozen).
 *
 * Build without floating-point contraction (-ffp-contract=off) and without
 * -ffast-math: the random normals (lpv_rng.c) must be the same bits as the
 * library's (lpvest/core/_rng.py), and several kernels sum in the library's order.
 */
#ifndef LPV_CORE_H
#define LPV_CORE_H

#include <stddef.h>
#include <stdint.h>

#if defined(LPV_TEST_EXPORTS)
#if defined _WIN32 || defined __CYGWIN__
#define LPV_API __declspec(dllexport)
#else
#define LPV_API __attribute__((visibility("default")))
#endif
#else
#define LPV_API
#endif

/* ---------------------------------------------------------------- kernels */

/* y = A x (A m x n), each y[i] summed over j = 0, 1, ... in order */
LPV_API void lpv_matvec(int m, int n, const double* A, const double* x, double* y);
/* C = A B (A m x k, B k x n), each entry summed over the inner index in order */
LPV_API void lpv_matmul(int m, int k, int n, const double* A, const double* B, double* C);
/* C = A B^T (A m x k, B n x k) */
LPV_API void lpv_matmul_bt(int m, int k, int n, const double* A, const double* B, double* C);
/* lower Cholesky factor L of the symmetric A (its lower triangle is read), the
 * textbook recurrence (as lpvest.estimators.kalman.recursion.small_chol_inverse);
 * returns 0, or 1 + the index of the first pivot that is not positive and finite
 * (then *pivot holds that pivot's value); *logdet (may be NULL) receives the sum of
 * the logarithms of the pivots before their square roots, as small_chol_inverse adds them */
LPV_API int lpv_cholesky(int n, const double* A, double* L, double* pivot, double* logdet);
/* the inverse of a lower triangular L by forward substitution on the identity
 * (as small_chol_inverse); Ci lower triangular */
LPV_API void lpv_lower_inverse(int n, const double* L, double* Ci);
/* solve A x = b in place (b: n x nrhs, row-major) by LU with partial pivoting; A is
 * overwritten by its factors; piv (n ints) is work space. Returns 0, or 1 when a
 * pivot is zero or not finite (A singular) */
LPV_API int lpv_lu_solve(int n, double* A, int* piv, double* b, int nrhs);
/* eigenvalues of the symmetric A (n x n; both triangles read, symmetrised), in
 * ascending order, by the cyclic Jacobi method; work: 2 n^2 doubles. Returns 0,
 * or 1 when it did not converge (never for finite input) */
LPV_API int lpv_sym_eigenvalues(int n, const double* A, double* w, double* work);
/* lower L with L L^T = P for a positive semidefinite P (lower triangle read): the
 * textbook recurrence, a zero column where the pivot is <= n eps max(diag P)
 * (lpvest.rng.psd_cholesky, the same bits) */
LPV_API void lpv_psd_cholesky(int n, const double* P, double* L);
/* out = L z for a lower triangular L, each entry summed L[i,0] z[0] + L[i,1] z[1] + ...
 * (lpvest.rng.lower_times, the same bits) */
LPV_API void lpv_lower_times(int n, const double* L, const double* z, double* out);

/* ------------------------------------------------------ random generator */

/* PCG64 (XSL-RR 128/64), the bit generator of numpy.random.PCG64 */
typedef struct {
    uint64_t state_hi, state_lo, inc_hi, inc_lo;
} lpv_pcg64;

/* seeded as numpy.random.PCG64(numpy.random.SeedSequence(entropy)), where the
 * entropy is the integer whose little-endian 32-bit words are words[0..n-1]
 * (a seed below 2^32: one word) */
LPV_API void lpv_pcg64_seed(lpv_pcg64* g, const uint32_t* words, int n);
/* the next raw 64-bit word */
LPV_API uint64_t lpv_pcg64_next(lpv_pcg64* g);
/* uniform in [0, 1): (w >> 11) 2^-53 */
LPV_API double lpv_uniform(lpv_pcg64* g);
/* standard normal: AS 241 at ((w >> 12) + 1/2) 2^-52 (lpvest.rng) */
LPV_API double lpv_normal(lpv_pcg64* g);
/* the normal quantile (AS 241) and its logarithm, as lpvest.rng computes them */
LPV_API double lpv_normal_quantile(double p);
LPV_API double lpv_log(double x);

/* ------------------------------------------------ formula virtual machine */

/* A formula of lpvest's safe language (lpvest/core/_expressions.py), compiled by the
 * exporter from the parsed syntax tree (never from text) into code words:
 *   LPV_OP_CONST k   push constants[k]
 *   LPV_OP_VAR k     push variables[k] (a scheduling component or a parameter)
 *   LPV_OP_ADD, SUB, MUL, DIV, POW     pop b, pop a, push a op b
 *   LPV_OP_NEG       negate the top
 *   LPV_OP_CALL f    apply function f (LPV_FN_*) to the top
 *   LPV_OP_END       the value is the top
 * Arithmetic is IEEE: a division by zero gives inf, a negative number to a
 * fractional power NaN, as numpy does; the caller checks what must be finite. */
enum {
    LPV_OP_END = 0,
    LPV_OP_CONST = 1,
    LPV_OP_VAR = 2,
    LPV_OP_ADD = 3,
    LPV_OP_SUB = 4,
    LPV_OP_MUL = 5,
    LPV_OP_DIV = 6,
    LPV_OP_POW = 7,
    LPV_OP_NEG = 8,
    LPV_OP_CALL = 9
};
/* the functions of lpvest.expressions.FUNCTIONS, in this order */
enum {
    LPV_FN_SIN = 0,
    LPV_FN_COS,
    LPV_FN_TAN,
    LPV_FN_EXP,
    LPV_FN_LOG,
    LPV_FN_SQRT,
    LPV_FN_SINH,
    LPV_FN_COSH,
    LPV_FN_TANH,
    LPV_FN_ARCTAN,
    LPV_FN_ABS,
    LPV_FN_COUNT
};
/* the deepest stack a formula may need (the exporter checks it) */
#define LPV_VM_STACK 128

typedef struct {
    const int32_t* code;     /* code words, ending with LPV_OP_END */
    const double* constants; /* the constant pool */
} lpv_formula;

/* the value of a formula (NaN for code the exporter would never write) */
LPV_API double lpv_formula_eval(const lpv_formula* f, const double* variables);

#endif /* LPV_CORE_H */
