/*
 * lpvest native runtime: what several roles share: weighted stacks of matrices,
 * maps from the scheduling to vertex weights, basis functions, the simplex check.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "lpv.h"

void lpv_stack_at(const lpv_stack* s, const double* rows, const double* c, double* out) {
    const int w = s->width;
    for (int j = 0; j < w; j++) out[j] = c[0] * rows[j];
    for (int i = 1; i < s->n_terms; i++) {
        const double* r = rows + (size_t)i * w;
        const double ci = c[i];
        for (int j = 0; j < w; j++) out[j] = out[j] + ci * r[j];
    }
}

void lpv_map_eval(const lpv_map* map, const double* p, double* out, double* work) {
    if (map->kind == LPV_MAP_FORMULAS) {
        for (int i = 0; i < map->n_formulas; i++) out[i] = lpv_formula_eval(&map->formulas[i], p);
        return;
    }
    /* multilinear: lambda_j = (c_j(p) - lower_j) / (upper_j - lower_j); vertex v takes
     * lambda_j where bit j of v is set, else 1 - lambda_j (MultilinearSimplexMap.evaluate) */
    const int n = map->n_formulas;
    for (int j = 0; j < n; j++) {
        double c = lpv_formula_eval(&map->formulas[j], p);
        work[j] = (c - map->lower[j]) / (map->upper[j] - map->lower[j]);
    }
    for (int v = 0; v < map->n_out; v++) {
        double a = 1.0;
        for (int j = 0; j < n; j++) a *= ((v >> j) & 1) ? work[j] : 1.0 - work[j];
        out[v] = a;
    }
}

void lpv_basis_eval(int k, const lpv_formula* basis, const double* p, double* psi) {
    psi[0] = 1.0;
    for (int i = 0; i < k; i++) psi[i + 1] = lpv_formula_eval(&basis[i], p);
}

int lpv_check_simplex(const double* alpha, int n, const char* name, lpv_msg* err) {
    const double atol = 1e-9; /* lpvest.validation.SIMPLEX_ATOL */
    /* the sum correctly rounded (math.fsum) for the quick check: Neumaier's compensation */
    double sum = 0.0, comp = 0.0, lo = alpha[0];
    for (int i = 0; i < n; i++) {
        double x = alpha[i], t = sum + x;
        comp += fabs(sum) >= fabs(x) ? (sum - t) + x : (x - t) + sum;
        sum = t;
        if (x < lo) lo = x;
    }
    if (lo >= -atol && fabs((sum + comp) - 1.0) <= atol) return 0;
    char a[48];
    if (lo < -atol) {
        int imin = 0;
        for (int i = 1; i < n; i++)
            if (alpha[i] < alpha[imin]) imin = i;
        lpv_msgf(err, "SchedulingRangeError: %s is not on the unit simplex: %s[%d] = %s < 0", name, name, imin + 1,
                 lpv_fmt_g(a, alpha[imin], 6));
        return 1;
    }
    double total = alpha[0];
    for (int i = 1; i < n; i++) total += alpha[i];
    if (fabs(total - 1.0) > atol) {
        lpv_msgf(err, "SchedulingRangeError: %s is not on the unit simplex: its entries sum to %s, not 1", name,
                 lpv_fmt_g(a, total, 12));
        return 1;
    }
    return 0;
}

int lpv_check_psd(const double* M, int n, const char* name, int semidefinite, double* sym_out, lpv_msg* err) {
    /* lpvest.validation.check_symmetric, then check_positive_definite (eigenvalues at unit scale) */
    double scale = 0.0;
    for (int i = 0; i < n * n; i++)
        if (fabs(M[i]) > scale) scale = fabs(M[i]);
    char a[48], b[48];
    int e;
    if (scale > 0) {
        frexp(scale, &e);
        double asym = 0.0;
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) {
                double diff = fabs(ldexp(M[i * n + j], -e) - ldexp(M[j * n + i], -e));
                if (diff > asym) asym = diff;
            }
        asym = ldexp(asym, e);
        if (asym > 1e-10 * scale) {
            lpv_msgf(err, "NotPositiveDefiniteError: %s is not symmetric: max |%s - %s^T| = %s exceeds 1e-10 x max |%s| = %s",
                     name, name, name, lpv_fmt_g(a, asym, 3), name, lpv_fmt_g(b, 1e-10 * scale, 3));
            return 1;
        }
    }
    if (n == 0) return 0;
    double* work = (double*)malloc(sizeof(double) * (size_t)(4 * n * n + n));
    if (!work) {
        lpv_msgf(err, "MemoryError: out of memory checking %s", name);
        return 1;
    }
    double *sym = work, *w = work + n * n, *jw = w + n;
    double smax = 0.0;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            sym[i * n + j] = 0.5 * M[i * n + j] + 0.5 * M[j * n + i];
            if (fabs(sym[i * n + j]) > smax) smax = fabs(sym[i * n + j]);
        }
    if (sym_out) memcpy(sym_out, sym, sizeof(double) * (size_t)(n * n));
    frexp(smax, &e);
    for (int i = 0; i < n * n; i++) sym[i] = ldexp(sym[i], -e);
    lpv_sym_eigenvalues(n, sym, w, jw);
    double emax = 0.0;
    for (int i = 0; i < n; i++) {
        w[i] = ldexp(w[i], e);
        if (fabs(w[i]) > emax) emax = fabs(w[i]);
    }
    double tol = (n > 10 ? n : 10) * 2.220446049250313e-16 * emax;
    int rc = 0;
    if (semidefinite && w[0] < -tol) {
        lpv_msgf(err, "NotPositiveDefiniteError: %s is not positive semidefinite: smallest eigenvalue %s", name,
                 lpv_fmt_g(a, w[0], 3));
        rc = 1;
    } else if (!semidefinite && (emax == 0.0 || w[0] <= tol)) {
        lpv_msgf(err, "NotPositiveDefiniteError: %s is not positive definite: smallest eigenvalue %s (largest %s)", name,
                 lpv_fmt_g(a, w[0], 3), lpv_fmt_g(b, w[n - 1], 3));
        rc = 1;
    }
    free(work);
    return rc;
}
