/*
 * lpvest native runtime: the Kalman and TruncatedKalman roles
 * (lpvest.estimators.kalman: LPVKalmanFilter, covariance_step, kalman_step;
 * lpvest.estimators.truncated: TruncatedKalmanFilter).
 *
 * The same recursion in the same layout: per sample the packed matrix
 *   F(p) = z(p) @ packed,  z = [1, psi_1, ..., psi_k, psi_i psi_j (i <= j)],
 *   F = [[A, B, GQG, 0, GSH], [I, 0, 0, 0, 0], [C, D, GSH^T, 0, HRH]]
 * (KalmanModel), V = E P E^T + W with E = F[:, :n] and W = F[:, n + nu:], the
 * gains [K; L] = V_12 Omega^-1 by the Cholesky factor of Omega = V_22 (for
 * n_y <= 3 its inverse by forward substitution, as small_chol_inverse; the
 * same bits for that factor), Joseph-form covariances (M V M^T, M = [I, -[K; L]]),
 * symmetrised. The truncated filter re-runs the recursion over the last tau + 1
 * samples from (6a) with ERRATA's correction, exactly the library's prior.
 *
 * Its steady-state start (start = "steady-state") solves the filter's discrete
 * algebraic Riccati equation at start_p with the structured doubling algorithm
 * (Chu, Fan, Lin 2005) after removing the cross term (A - S R^-1 C, Q - S R^-1 S^T);
 * the library uses scipy's solve_discrete_are. Both are backward stable; their
 * difference is bounded by the DARE's condition (tests/test_native_fmus.py).
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "lpv.h"

#define KD(c) ((const lpv_kalman_data*)(c)->model->data)

static const double LOG_2PI = 0x1.d67f1c864beb4p+0; /* math.log(2 pi) */

typedef struct {
    int n, nu, m, R, C, n2, fsize;
} dims;

static dims dims_of(const lpv_kalman_data* d) {
    dims q;
    q.n = d->nx, q.nu = d->nu, q.m = d->ny;
    q.R = d->f_rows, q.C = d->f_cols;
    q.n2 = 2 * d->nx;
    q.fsize = d->f_rows * d->f_cols;
    return q;
}

/* work space of one covariance step: doubles (work_size) and ints (work_ints) */
typedef struct {
    double *EP, *EPT, *V, *gains, *Ci, *L, *Z, *MV, *PP, *col;
    int* nnz; /* per row of E = F[:, :n]: k when it is e_k (a row of the identity), else < 0 */
} work;

static size_t work_size(dims q) {
    return 2 * (size_t)q.R * q.n + (size_t)q.R * q.R + (size_t)q.n2 * q.m + 2 * (size_t)q.m * q.m + (size_t)q.m * (q.n2 + q.m + 1) +
           (size_t)q.n2 * q.R + (size_t)q.n2 * q.n2 + (size_t)q.R + 8;
}

static size_t work_ints(dims q) { return (size_t)q.R; }

/* the ints before the work space's: the pivots of the steady state's solves */
#define PIVOTS(q) ((size_t)((q).n + (q).m + 1))

static work work_at(double* base, int* ibase, dims q) {
    work w;
    w.EP = base, base += (size_t)q.R * q.n;
    w.EPT = base, base += (size_t)q.R * q.n;
    w.V = base, base += (size_t)q.R * q.R;
    w.gains = base, base += (size_t)q.n2 * q.m;
    w.Ci = base, base += (size_t)q.m * q.m;
    w.L = base, base += (size_t)q.m * q.m;
    w.Z = base, base += (size_t)q.m * (q.n2 + q.m + 1);
    w.MV = base, base += (size_t)q.n2 * q.R;
    w.PP = base, base += (size_t)q.n2 * q.n2;
    w.col = base;
    w.nnz = ibase;
    return w;
}

static void singular(lpv_msg* err, long t, const char* detail) {
    if (t >= 0) lpv_msgf(err, "NumericalError: the innovation covariance Omega_t is not positive definite at t=%ld: %s", t, detail);
    else lpv_msgf(err, "NumericalError: the innovation covariance Omega_t is not positive definite: %s", detail);
}

/* covariance_step(P, F, t, rhs): V, Omega (= V[n2:, n2:]), gains, the joint PP; whitened and logdet */
static int covariance_step(dims q, const double* P, const double* F, long t, const double* rhs, double* whitened,
                           double* logdet, work* w, lpv_msg* err) {
    const int n = q.n, m = q.m, R = q.R, n2 = q.n2, wcol = n + q.nu;
    /* E = F[:, :n] (rows of F, stride C); EP = E @ P; V = EP @ E^T + F[:, wcol:], each entry summed over
     * k = 0, 1, ... in order. A row of E that is a row of the identity (the rows [I 0] of the layout) is
     * not multiplied out: its sums are one term, 1 x, and the other terms 0 y add nothing to it (finite
     * numbers), so E_k P = P_k and (EP)_i E_k^T = (EP)_ik are the same numbers as the full sums. */
    for (int i = 0; i < R; i++) {
        const double* Fi = F + i * q.C;
        int unit = -1;
        for (int k = 0; k < n; k++)
            if (Fi[k] != 0.0) {
                if (Fi[k] != 1.0 || unit >= 0) {
                    unit = -2;
                    break;
                }
                unit = k;
            }
        w->nnz[i] = unit; /* k when row i of E is e_k, else < 0 */
    }
    /* EP row by row, EP_i = E_i0 P_0 + E_i1 P_1 + ... (rows of P); then V column by column over its
     * rows at once, V_.j = EP_.0 E_j0 + EP_.1 E_j1 + ... (columns of EP, kept as the rows of EPT): the
     * same terms in the same order per entry, in loops the compiler vectorises */
    for (int i = 0; i < R; i++) {
        const double* Fi = F + i * q.C;
        double* EPi = w->EP + i * n;
        if (w->nnz[i] >= 0) {
            memcpy(EPi, P + w->nnz[i] * n, sizeof(double) * (size_t)n);
        } else {
            for (int j = 0; j < n; j++) EPi[j] = Fi[0] * P[j];
            for (int k = 1; k < n; k++) {
                const double e = Fi[k];
                const double* Pk = P + k * n;
                for (int j = 0; j < n; j++) EPi[j] = EPi[j] + e * Pk[j];
            }
        }
        for (int j = 0; j < n; j++) w->EPT[j * R + i] = EPi[j];
    }
    for (int j = 0; j < R; j++) {
        const double* Fj = F + j * q.C;
        const double* W = F + wcol + j; /* W_ij = W[i * C] */
        double* col = w->col;
        if (w->nnz[j] >= 0) {
            const double* EPk = w->EPT + w->nnz[j] * R;
            for (int i = 0; i < R; i++) w->V[i * R + j] = EPk[i] + W[i * q.C];
            continue;
        }
        for (int i = 0; i < R; i++) col[i] = w->EPT[i] * Fj[0];
        for (int k = 1; k < n; k++) {
            const double e = Fj[k];
            const double* EPk = w->EPT + k * R;
            for (int i = 0; i < R; i++) col[i] = col[i] + EPk[i] * e;
        }
        for (int i = 0; i < R; i++) w->V[i * R + j] = col[i] + W[i * q.C];
    }
    const double* V = w->V;
    char a[48];
    if (m == 1) {
        double om = V[n2 * R + n2];
        if (!(om > 0.0 && om < HUGE_VAL)) {
            char detail[80];
            snprintf(detail, sizeof detail, "Omega_t = %s", lpv_fmt_g(a, om, 6));
            singular(err, t, detail);
            return 1;
        }
        for (int i = 0; i < n2; i++) w->gains[i] = V[i * R + n2] / om;
        if (rhs) whitened[0] = rhs[0] / sqrt(om);
        *logdet = log(om);
    } else {
        /* the factor of Omega by the textbook recurrence, its inverse by forward substitution (small_chol_inverse) */
        for (int i = 0; i < m; i++)
            for (int j = 0; j < m; j++) w->Z[i * m + j] = V[(n2 + i) * R + n2 + j];
        double pivot = 0.0;
        int bad = lpv_cholesky(m, w->Z, w->L, &pivot, logdet);
        if (bad) {
            char detail[80];
            snprintf(detail, sizeof detail, "Cholesky pivot %d is %s", bad, lpv_fmt_g(a, pivot, 3));
            singular(err, t, detail);
            return 1;
        }
        lpv_lower_inverse(m, w->L, w->Ci);
        /* Z = Ci @ V[n2:, :n2] (m x n2); gains = Z^T @ Ci (n2 x m) */
        for (int i = 0; i < m; i++)
            for (int j = 0; j < n2; j++) {
                double acc = w->Ci[i * m] * V[n2 * R + j];
                for (int k = 1; k < m; k++) acc += w->Ci[i * m + k] * V[(n2 + k) * R + j];
                w->Z[i * n2 + j] = acc;
            }
        for (int i = 0; i < n2; i++)
            for (int j = 0; j < m; j++) {
                double acc = w->Z[i] * w->Ci[j];
                for (int k = 1; k < m; k++) acc += w->Z[k * n2 + i] * w->Ci[k * m + j];
                w->gains[i * m + j] = acc;
            }
        if (rhs) lpv_matvec(m, m, w->Ci, rhs, whitened);
    }
    /* M = [I_n2, -gains] (n2 x R); PP = (M V) M^T; PP = (PP + PP^T) / 2. With the identity block the
     * sums over the inner index are V_ij (or (MV)_ij) plus the terms of the gains, in the same order:
     * MV_ij = V_ij + (-g_i0) V_(n2)j + ..., PP_ij = MV_ij + MV_i(n2) (-g_j0) + ... */
    for (int i = 0; i < n2; i++) {
        const double* gi = w->gains + i * m;
        double* MVi = w->MV + i * R;
        for (int j = 0; j < R; j++) {
            double acc = V[i * R + j];
            for (int k = 0; k < m; k++) acc += -gi[k] * V[(n2 + k) * R + j];
            MVi[j] = acc;
        }
    }
    for (int i = 0; i < n2; i++) {
        const double* MVi = w->MV + i * R;
        for (int j = 0; j < n2; j++) {
            const double* gj = w->gains + j * m;
            double acc = MVi[j];
            for (int k = 0; k < m; k++) acc += MVi[n2 + k] * -gj[k];
            w->PP[i * n2 + j] = acc;
        }
    }
    for (int i = 0; i < n2; i++)
        for (int j = 0; j < i; j++) {
            double s = w->PP[i * n2 + j] + w->PP[j * n2 + i];
            w->PP[i * n2 + j] = w->PP[j * n2 + i] = s * 0.5;
        }
    for (int i = 0; i < n2; i++) w->PP[i * n2 + i] = (w->PP[i * n2 + i] + w->PP[i * n2 + i]) * 0.5;
    return 0;
}

/* F(p) = z(p) @ packed */
static void step_matrices(const lpv_kalman_data* d, const double* packed, const double* p, double* zbuf, double* F,
                          int fsize) {
    int k = d->n_basis;
    double* psi = zbuf + d->n_z; /* psi_1..psi_k */
    for (int i = 0; i < k; i++) psi[i] = lpv_formula_eval(&d->basis[i], p);
    zbuf[0] = 1.0;
    for (int i = 0; i < k; i++) zbuf[1 + i] = psi[i];
    for (int r = 0; r < d->n_z - 1 - k; r++) zbuf[1 + k + r] = psi[d->pairs[2 * r] - 1] * psi[d->pairs[2 * r + 1] - 1];
    /* F[j] = z_0 packed_0[j] + z_1 packed_1[j] + ... in that order; term by term over the whole
     * matrix, the loops the compiler vectorises */
    for (int j = 0; j < fsize; j++) F[j] = zbuf[0] * packed[j];
    for (int i = 1; i < d->n_z; i++) {
        const double zi = zbuf[i];
        const double* row = packed + (size_t)i * fsize;
        for (int j = 0; j < fsize; j++) F[j] = F[j] + zi * row[j];
    }
}

/* ----------------------------------------------------------- layouts */

typedef struct {
    size_t packed, x0, P0, start;
} cfg_layout;
typedef struct {
    size_t x, P, t, loglik, count, head, window; /* window: Kalman none */
} st_layout;
typedef struct {
    size_t F, z, h, xu, xi, white, xs, prior, w;
} tmp_layout;

static int truncated(const lpv_comp* c) { return c->model->role == LPV_ROLE_TRUNCATED; }

static cfg_layout cfg_of(const lpv_kalman_data* d) {
    dims q = dims_of(d);
    cfg_layout l;
    l.packed = 0;
    l.x0 = (size_t)d->n_z * q.fsize;
    l.P0 = l.x0 + q.n;
    l.start = l.P0 + (size_t)q.n * q.n;
    return l;
}

static st_layout st_of(const lpv_kalman_data* d, int trunc) {
    dims q = dims_of(d);
    st_layout l;
    l.x = 0;
    l.P = l.x + q.n;
    l.t = l.P + (trunc ? 0 : (size_t)q.n * q.n);
    l.loglik = l.t + 1;
    l.count = l.loglik + 1;
    l.head = l.count + 1;
    l.window = l.head + 1;
    return l;
}

static tmp_layout tmp_of(const lpv_kalman_data* d) {
    dims q = dims_of(d);
    tmp_layout l;
    l.F = 0;
    l.z = l.F + q.fsize;
    l.h = l.z + (size_t)d->n_z + d->n_basis + 1;
    l.xu = l.h + q.R;
    l.xi = l.xu + q.n + q.nu + 1;
    l.white = l.xi + q.m;
    l.xs = l.white + q.m;
    l.prior = l.xs + q.n2;
    l.w = l.prior + 2 * (size_t)q.n * q.n;
    return l;
}

/* --------------------------------------------------- steady state (DARE) */

/* solve A X = B in place for square A (n x n) and B (n x k) by LU: returns nonzero when singular */
static int solve(int n, double* A, double* B, int k, int* piv) { return lpv_lu_solve(n, A, piv, B, k); }

/* The stabilising solution X of X = Ab X Ab^T - Ab X C^T (R + C X C^T)^-1 C X Ab^T + Qb
 * (the filter DARE without cross term) by the structured doubling algorithm on the dual
 * (control) form: A_0 = Ab^T, G_0 = C^T R^-1 C, H_0 = Qb; H_k -> X.
 * scratch: 8 n^2 + n m + ... doubles; returns 0 or nonzero (no convergence). */
static int sda(int n, int m, const double* Ab, const double* C, const double* Rm, const double* Qb, double* X,
               double* scratch, int* piv) {
    double* A = scratch;
    double* G = A + n * n;
    double* H = G + n * n;
    double* W = H + n * n;
    double* T1 = W + n * n;
    double* T2 = T1 + n * n;
    double* T3 = T2 + n * n;
    double* RC = T3 + n * n; /* m x n, then m x m */
    double* Rc = RC + m * n;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) A[i * n + j] = Ab[j * n + i], H[i * n + j] = Qb[i * n + j];
    /* G = C^T R^-1 C: solve R Y = C, G = C^T Y */
    memcpy(Rc, Rm, sizeof(double) * (size_t)(m * m));
    memcpy(RC, C, sizeof(double) * (size_t)(m * n));
    if (solve(m, Rc, RC, n, piv)) return 1;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            double acc = 0.0;
            for (int k = 0; k < m; k++) acc += C[k * n + i] * RC[k * n + j];
            G[i * n + j] = acc;
        }
    for (int it = 0; it < 100; it++) {
        /* W = I + G H */
        lpv_matmul(n, n, n, G, H, W);
        for (int i = 0; i < n; i++) W[i * n + i] += 1.0;
        /* T1 = W^-1 A, T2 = W^-1 G (solve with copies of W) */
        memcpy(T3, W, sizeof(double) * (size_t)(n * n));
        memcpy(T1, A, sizeof(double) * (size_t)(n * n));
        if (solve(n, T3, T1, n, piv)) return 1;
        memcpy(T3, W, sizeof(double) * (size_t)(n * n));
        memcpy(T2, G, sizeof(double) * (size_t)(n * n));
        if (solve(n, T3, T2, n, piv)) return 1;
        /* H' = H + A^T H W^-1 A = H + A^T (H T1) */
        lpv_matmul(n, n, n, H, T1, T3); /* H T1 */
        double change = 0.0, size = 0.0;
        double* Hn = X; /* the new H, then copied */
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) {
                double acc = 0.0;
                for (int k = 0; k < n; k++) acc += A[k * n + i] * T3[k * n + j];
                Hn[i * n + j] = H[i * n + j] + acc;
            }
        /* G' = G + A W^-1 G A^T = G + A (T2 A^T) */
        lpv_matmul_bt(n, n, n, T2, A, T3); /* T2 A^T */
        double* Gn = W;
        lpv_matmul(n, n, n, A, T3, Gn);
        for (int i = 0; i < n * n; i++) Gn[i] += G[i];
        /* A' = A W^-1 A = A T1 */
        lpv_matmul(n, n, n, A, T1, T3);
        for (int i = 0; i < n * n; i++) {
            change += fabs(Hn[i] - H[i]);
            size += fabs(Hn[i]);
            if (!isfinite(Hn[i])) return 1;
        }
        memcpy(H, Hn, sizeof(double) * (size_t)(n * n));
        memcpy(G, Gn, sizeof(double) * (size_t)(n * n));
        memcpy(A, T3, sizeof(double) * (size_t)(n * n));
        if (change <= 1e-15 * size) {
            for (int i = 0; i < n; i++)
                for (int j = 0; j < n; j++) X[i * n + j] = 0.5 * (H[i * n + j] + H[j * n + i]);
            return 0;
        }
    }
    return 1;
}

/* the posterior steady-state covariance at p (steady_state(...).P_filt) into out */
static int steady_state(lpv_comp* c, const double* p, double* out, lpv_msg* err) {
    const lpv_kalman_data* d = KD(c);
    dims q = dims_of(d);
    cfg_layout l = cfg_of(d);
    tmp_layout t = tmp_of(d);
    const int n = q.n, m = q.m, wc = n + q.nu;
    double* F = c->tmp + t.F;
    step_matrices(d, c->cfg + l.packed, p, c->tmp + t.z, F, q.fsize);
    /* A, C, GQG, GSH, HRH from F */
    double* base = c->tmp + t.w + work_size(q);
    double *A = base, *Cm = A + n * n, *Q = Cm + m * n, *S = Q + n * n, *Rm = S + n * m, *Ab = Rm + m * m,
           *Qb = Ab + n * n, *J = Qb + n * n, *RS = J + n * m, *X = RS + m * n, *scratch = X + n * n;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) A[i * n + j] = F[i * q.C + j], Q[i * n + j] = F[i * q.C + wc + j];
    for (int i = 0; i < m; i++)
        for (int j = 0; j < n; j++) Cm[i * n + j] = F[(q.n2 + i) * q.C + j];
    for (int i = 0; i < n; i++)
        for (int j = 0; j < m; j++) S[i * m + j] = F[i * q.C + wc + q.n2 + j];
    for (int i = 0; i < m; i++)
        for (int j = 0; j < m; j++) Rm[i * m + j] = F[(q.n2 + i) * q.C + wc + q.n2 + j];
    char list[512];
    /* J = S R^-1 (solve R J^T = S^T), Ab = A - J C, Qb = Q - J S^T */
    double* Rc = scratch;
    memcpy(Rc, Rm, sizeof(double) * (size_t)(m * m));
    for (int i = 0; i < m; i++)
        for (int j = 0; j < n; j++) RS[i * n + j] = S[j * m + i];
    if (solve(m, Rc, RS, n, c->itmp)) {
        lpv_msgf(err, "NumericalError: no stabilising steady-state Riccati solution at p = %s: H R H^T is singular",
                 lpv_repr_list(list, sizeof list, p, d->n_p));
        return 1;
    }
    for (int i = 0; i < n; i++)
        for (int j = 0; j < m; j++) J[i * m + j] = RS[j * n + i];
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) {
            double jc = 0.0, js = 0.0;
            for (int k = 0; k < m; k++) jc += J[i * m + k] * Cm[k * n + j], js += J[i * m + k] * S[j * m + k];
            Ab[i * n + j] = A[i * n + j] - jc;
            Qb[i * n + j] = Q[i * n + j] - js;
        }
    if (sda(n, m, Ab, Cm, Rm, Qb, X, scratch, c->itmp)) {
        lpv_msgf(err, "NumericalError: no stabilising steady-state Riccati solution at p = %s: the doubling "
                 "iteration did not converge", lpv_repr_list(list, sizeof list, p, d->n_p));
        return 1;
    }
    /* P_filt = covariance_step(P_inf, F(p)).joint[n:, n:] */
    work w = work_at(c->tmp + t.w, c->itmp + PIVOTS(q), q);
    double logdet;
    if (covariance_step(q, X, F, -1, NULL, NULL, &logdet, &w, err)) return 1;
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) out[i * n + j] = w.PP[(n + i) * q.n2 + n + j];
    return 0;
}

/* ------------------------------------------------------------- the role */

static int sizes(const lpv_model* m, const lpv_values* v, const double* mp, lpv_sizes* out, lpv_msg* err) {
    (void)mp;
    const lpv_kalman_data* d = (const lpv_kalman_data*)m->data;
    dims q = dims_of(d);
    int trunc = m->role == LPV_ROLE_TRUNCATED;
    size_t window = 0;
    if (trunc) {
        int tau = lpv_param_int(m, v, "tau", 0);
        window = ((size_t)tau + 1) * (size_t)q.fsize;
        if ((double)window > 1e9) {
            lpv_msgf(err, "MemoryError: tau = %d keeps %.3g numbers; too many", tau, (double)window);
            return 1;
        }
        const char* start = lpv_param_string(m, v, "start");
        if (!start || (strcmp(start, "theorem") != 0 && strcmp(start, "steady-state") != 0)) {
            char a[320];
            lpv_abbreviate(a, sizeof a, start ? start : "", start ? strlen(start) : 0, 30);
            lpv_msgf(err, "LpvestError: start = %s; expected one of theorem, steady-state", a);
            return 1;
        }
        if (strcmp(start, "theorem") == 0 && !d->theorem_start) {
            lpv_msgf(err, "NotPositiveDefiniteError: %s", d->theorem_error ? d->theorem_error : "no theorem start");
            return 1;
        }
    } else {
        const double* P0 = lpv_param_reals(m, v, "P0");
        if (!P0) {
            lpv_msgf(err, "LpvestError: this filter has no parameter P0");
            return 1;
        }
        if (lpv_check_psd(P0, q.n, "P0", 1, NULL, err)) return 1;
    }
    cfg_layout c = cfg_of(d);
    st_layout s = st_of(d, trunc);
    tmp_layout t = tmp_of(d);
    out->n_cfg = c.start + (size_t)q.n * q.n;
    out->n_st = s.window + window;
    out->n_words = 0;
    out->n_tmp = t.w + work_size(q) + 16 * (size_t)(q.n + q.m + 2) * (q.n + q.m + 2);
    out->n_itmp = PIVOTS(q) + work_ints(q);
    return 0;
}

static int configure(lpv_comp* c, const lpv_values* v, const double* mp, lpv_msg* err) {
    const lpv_model* m = c->model;
    const lpv_kalman_data* d = KD(c);
    dims q = dims_of(d);
    cfg_layout l = cfg_of(d);
    memcpy(c->cfg + l.packed, d->packed, sizeof(double) * (size_t)d->n_z * q.fsize);
    lpv_apply_entries(m, 0, mp, c->cfg + l.packed);
    const double* x0 = lpv_param_reals(m, v, "x0");
    const double* P0 = lpv_param_reals(m, v, "P0");
    if (x0 && P0) { /* the Kalman FMU's parameters; the symmetrised P0 (check_positive_definite, checked in sizes()) */
        memcpy(c->cfg + l.x0, x0, sizeof(double) * (size_t)q.n);
        lpv_check_psd(P0, q.n, "P0", 1, c->cfg + l.P0, err);
    } else { /* the TruncatedKalman FMU: the model's x0 and P0 */
        memcpy(c->cfg + l.x0, d->x0, sizeof(double) * (size_t)q.n);
        memcpy(c->cfg + l.P0, d->P0, sizeof(double) * (size_t)q.n * q.n);
    }
    if (truncated(c)) {
        c->values[0] = lpv_param_int(m, v, "tau", 0);
        const char* start = lpv_param_string(m, v, "start");
        if (strcmp(start, "theorem") == 0) {
            memcpy(c->cfg + l.start, d->theorem_start, sizeof(double) * (size_t)q.n * q.n);
        } else {
            const double* p = lpv_param_reals(m, v, "start_p");
            /* the range check of KalmanModel.matrices (check_p) */
            for (int j = 0; j < d->n_p; j++) {
                double lo = d->box_lower[j], hi = d->box_upper[j];
                double big = fabs(lo) > fabs(hi) ? fabs(lo) : fabs(hi);
                double tol = 1e-12 * (big > 1.0 ? big : 1.0);
                if (p[j] < lo - tol || p[j] > hi + tol) {
                    char a[48], b[48], e[48];
                    double shown_back;
                    lpv_fmt_g(a, p[j], 6);
                    shown_back = 0.0;
                    lpv_parse_float(a, strlen(a), &shown_back);
                    if (shown_back != p[j]) lpv_repr(a, p[j]);
                    lpv_msgf(err,
                             "SchedulingRangeError: parameter start_p[%d] (scheduling variable %s) = %s is outside its "
                             "declared range [%s, %s]",
                             j + 1, d->names[j], a, lpv_fmt_g(b, lo, 6), lpv_fmt_g(e, hi, 6));
                    return 1;
                }
            }
            if (steady_state(c, p, c->cfg + l.start, err)) return 1;
        }
    }
    return 0;
}

static void reset(lpv_comp* c, double t0) {
    (void)t0;
    const lpv_kalman_data* d = KD(c);
    dims q = dims_of(d);
    cfg_layout l = cfg_of(d);
    st_layout s = st_of(d, truncated(c));
    memcpy(c->st + s.x, c->cfg + l.x0, sizeof(double) * (size_t)q.n);
    if (!truncated(c)) memcpy(c->st + s.P, c->cfg + l.P0, sizeof(double) * (size_t)q.n * q.n);
    c->st[s.t] = 0.0;
    c->st[s.loglik] = 0.0;
    c->st[s.count] = 0.0;
    c->st[s.head] = 0.0;
}

/* the truncated prior P^(tau)_{t|t-1} (truncated_prior) into P */
static int truncated_prior(lpv_comp* c, double* P, lpv_msg* err) {
    const lpv_kalman_data* d = KD(c);
    dims q = dims_of(d);
    cfg_layout l = cfg_of(d);
    st_layout s = st_of(d, 1);
    tmp_layout t = tmp_of(d);
    const int n = q.n, tau = (int)c->values[0];
    long now = (long)c->st[s.t];
    int k = (int)c->st[s.count], head = (int)c->st[s.head];
    const double* window = c->st + s.window;
    work w = work_at(c->tmp + t.w, c->itmp + PIVOTS(q), q);
    int first;
    if (now <= tau) {
        memcpy(P, c->cfg + l.P0, sizeof(double) * (size_t)n * n);
        first = 0;
    } else {
        /* (6a) with ERRATA at the oldest kept sample: Abar P_start Abar^T + G Qbar G^T (restart_covariance) */
        const double* F = window + (size_t)head * q.fsize;
        const int m = q.m, wc = n + q.nu;
        double* J = w.Z;  /* n x m */
        double* Abar = w.MV; /* n x n */
        double* GQb = Abar + n * n;
        double* T = w.EP; /* n x n */
        /* HRH, GSH, A, C, GQG of F */
        for (int i = 0; i < m; i++)
            for (int j = 0; j < m; j++) w.V[i * m + j] = F[(q.n2 + i) * q.C + wc + q.n2 + j];
        double pivot = 0.0;
        if (lpv_cholesky(m, w.V, w.L, &pivot, NULL)) {
            lpv_msgf(err, "NotPositiveDefiniteError: H(p) R H(p)^T is singular at t=%ld: the decorrelated form (5c)/(5e) "
                     "needs it invertible (H of full row rank)", now - k);
            return 1;
        }
        lpv_lower_inverse(m, w.L, w.Ci);
        /* J = (Ci @ GSH^T)^T @ Ci: Y = Ci GSH^T (m x n), J = Y^T Ci (n x m) */
        double* Y = w.gains;
        for (int i = 0; i < m; i++)
            for (int j = 0; j < n; j++) {
                double acc = w.Ci[i * m] * F[j * q.C + wc + q.n2];
                for (int kk = 1; kk < m; kk++) acc += w.Ci[i * m + kk] * F[j * q.C + wc + q.n2 + kk];
                Y[i * n + j] = acc;
            }
        for (int i = 0; i < n; i++)
            for (int j = 0; j < m; j++) {
                double acc = Y[i] * w.Ci[j];
                for (int kk = 1; kk < m; kk++) acc += Y[kk * n + i] * w.Ci[kk * m + j];
                J[i * m + j] = acc;
            }
        /* Abar = A - J C; GQG2 = GQG - J GSH^T; GQbarG = (GQG2 + GQG2^T) / 2 */
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) {
                double jc = J[i * m] * F[q.n2 * q.C + j], js = J[i * m] * F[j * q.C + wc + q.n2];
                for (int kk = 1; kk < m; kk++) {
                    jc += J[i * m + kk] * F[(q.n2 + kk) * q.C + j];
                    js += J[i * m + kk] * F[j * q.C + wc + q.n2 + kk];
                }
                Abar[i * n + j] = F[i * q.C + j] - jc;
                GQb[i * n + j] = F[i * q.C + wc + j] - js;
            }
        for (int i = 0; i < n; i++)
            for (int j = 0; j <= i; j++) {
                double a = GQb[i * n + j], b = GQb[j * n + i];
                GQb[i * n + j] = 0.5 * (a + b);
                GQb[j * n + i] = 0.5 * (b + a);
            }
        /* P = Abar P_start Abar^T + GQbarG, symmetrised */
        lpv_matmul(n, n, n, Abar, c->cfg + l.start, T);
        lpv_matmul_bt(n, n, n, T, Abar, P);
        for (int i = 0; i < n * n; i++) P[i] = P[i] + GQb[i];
        for (int i = 0; i < n; i++)
            for (int j = 0; j <= i; j++) {
                double a = P[i * n + j], b = P[j * n + i];
                P[i * n + j] = 0.5 * (a + b);
                P[j * n + i] = 0.5 * (b + a);
            }
        first = 1;
    }
    double logdet;
    for (int i = first; i < k; i++) {
        const double* F = window + (size_t)((head + i) % (tau + 1)) * q.fsize;
        if (covariance_step(q, P, F, now - k + i, NULL, NULL, &logdet, &w, err)) return 1;
        for (int r = 0; r < n; r++)
            for (int col = 0; col < n; col++) P[r * n + col] = w.PP[r * q.n2 + col];
    }
    return 0;
}

static int evaluate(lpv_comp* c, const double* in, double* out, lpv_msg* err) {
    const lpv_kalman_data* d = KD(c);
    dims q = dims_of(d);
    cfg_layout l = cfg_of(d);
    int trunc = truncated(c);
    st_layout s = st_of(d, trunc);
    tmp_layout t = tmp_of(d);
    const int n = q.n, m = q.m, n2 = q.n2;
    double* F = c->tmp + t.F;
    step_matrices(d, c->cfg + l.packed, in + d->in_p, c->tmp + t.z, F, q.fsize);
    const double* x = c->st + s.x;
    double* P = c->tmp + t.prior;
    if (trunc) {
        if (truncated_prior(c, P, err)) return 1;
    } else {
        memcpy(P, c->st + s.P, sizeof(double) * (size_t)n * n);
    }
    /* h = F[:, :n + nu] @ [x; u] */
    double* xu = c->tmp + t.xu;
    memcpy(xu, x, sizeof(double) * (size_t)n);
    if (q.nu) memcpy(xu + n, in + d->in_u, sizeof(double) * (size_t)q.nu);
    double* h = c->tmp + t.h;
    for (int i = 0; i < q.R; i++) {
        double acc = F[i * q.C] * xu[0];
        for (int j = 1; j < n + q.nu; j++) acc += F[i * q.C + j] * xu[j];
        h[i] = acc;
    }
    double* xi = c->tmp + t.xi;
    for (int i = 0; i < m; i++) xi[i] = in[d->in_y + i] - h[n2 + i];
    double* white = c->tmp + t.white;
    work w = work_at(c->tmp + t.w, c->itmp + PIVOTS(q), q);
    double logdet = 0.0;
    if (covariance_step(q, P, F, (long)c->st[s.t], xi, white, &logdet, &w, err)) return 1;
    double* xs = c->tmp + t.xs;
    for (int i = 0; i < n2; i++) {
        double acc = w.gains[i * m] * xi[0];
        for (int j = 1; j < m; j++) acc += w.gains[i * m + j] * xi[j];
        xs[i] = h[i] + acc;
    }
    double zz = white[0] * white[0];
    for (int i = 1; i < m; i++) zz += white[i] * white[i];
    double ll = -0.5 * (m * LOG_2PI + logdet + zz);
    c->values[1] = ll;
    /* outputs */
    memcpy(out + d->out_xhat, xs + n, sizeof(double) * (size_t)n);
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) out[d->out_P + i * n + j] = w.PP[(n + i) * n2 + n + j];
    memcpy(out + d->out_xpred, xs, sizeof(double) * (size_t)n);
    if (d->out_Ppred >= 0)
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) out[d->out_Ppred + i * n + j] = w.PP[i * n2 + j];
    memcpy(out + d->out_yhat, h + n2, sizeof(double) * (size_t)m);
    memcpy(out + d->out_innovation, xi, sizeof(double) * (size_t)m);
    for (int i = 0; i < n; i++)
        for (int j = 0; j < m; j++) out[d->out_K + i * m + j] = w.gains[i * m + j];
    for (int i = 0; i < m; i++)
        for (int j = 0; j < m; j++) out[d->out_Omega + i * m + j] = w.V[(n2 + i) * q.R + n2 + j];
    if (d->out_loglik >= 0) out[d->out_loglik] = c->st[s.loglik] + ll;
    /* kept for the step: the next prior in tmp (P_{t+1|t}) is w.PP[:n, :n] */
    return 0;
}

static int commit(lpv_comp* c, double t_end, lpv_msg* err) {
    (void)t_end, (void)err;
    const lpv_kalman_data* d = KD(c);
    dims q = dims_of(d);
    int trunc = truncated(c);
    st_layout s = st_of(d, trunc);
    tmp_layout t = tmp_of(d);
    const int n = q.n;
    work w = work_at(c->tmp + t.w, c->itmp + PIVOTS(q), q);
    memcpy(c->st + s.x, c->tmp + t.xs, sizeof(double) * (size_t)n);
    if (!trunc) {
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) c->st[s.P + i * n + j] = w.PP[i * q.n2 + j];
    } else {
        int tau = (int)c->values[0];
        int k = (int)c->st[s.count], head = (int)c->st[s.head];
        int slot;
        if (k == tau + 1) {
            slot = head;
            c->st[s.head] = (double)((head + 1) % (tau + 1));
        } else {
            slot = (head + k) % (tau + 1);
            c->st[s.count] = k + 1;
        }
        memcpy(c->st + s.window + (size_t)slot * q.fsize, c->tmp + t.F, sizeof(double) * (size_t)q.fsize);
    }
    c->st[s.t] += 1.0;
    c->st[s.loglik] += c->values[1];
    return 0;
}

/* a restored state: the sample counter a whole number in [0, 2^53]; the truncated filter's
 * window count in [0, min(t, tau + 1)] and its head in [0, tau], whole (indices into the window) */
static int check_state(const lpv_comp* c, lpv_msg* err) {
    const lpv_kalman_data* d = KD(c);
    st_layout s = st_of(d, truncated(c));
    double t = c->st[s.t];
    if (!(t >= 0.0 && t <= 9007199254740992.0 && t == floor(t))) {
        lpv_msgf(err, "ArgumentError: the state's sample counter %.17g is not a whole number >= 0", t);
        return 1;
    }
    if (truncated(c)) {
        double tau = c->values[0], count = c->st[s.count], head = c->st[s.head];
        if (!(count >= 0.0 && count <= tau + 1.0 && count <= t && count == floor(count) && head >= 0.0 &&
              head <= tau && head == floor(head))) {
            lpv_msgf(err, "ArgumentError: the state's window (%.17g samples from %.17g) does not fit tau = %.17g",
                     count, head, tau);
            return 1;
        }
    }
    return 0;
}

static const lpv_role KALMAN = {sizes, configure, reset, NULL, evaluate, commit, check_state};
static const lpv_role TRUNCATED = {sizes, configure, reset, NULL, evaluate, commit, check_state};

const lpv_role* lpv_role_kalman(void) { return &KALMAN; }
const lpv_role* lpv_role_truncated(void) { return &TRUNCATED; }
