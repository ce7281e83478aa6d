/*
 * lpvest native runtime: the HinfPD and HinfRobust roles (lpvest.estimators.hinf.HinfFilter).
 *
 * Peixoto et al.'s filter (2) with the design the FMU was built with:
 *   x_{f,k+1} = H(alpha_k)^-1 (A_f(alpha_k) x_{f,k} + B_f(alpha_k) y_k)
 *   z_{f,k}   = C_f(alpha_k) x_{f,k} + D_f(alpha_k) y_k
 * the matrices the design's vertex matrices weighted by alpha (a robust design:
 * one set), H^-1 applied by an LU solve with partial pivoting. alpha is an input
 * (checked to lie on the simplex) or the plant's map of the scheduling input p.
 * A plant with a known input u: the filter runs the plant's response to u
 * (x_u) beside (2), feeds (2) with y - Cy x_u - Dyu u and adds Cz x_u + Dzu u
 * back (lpvest.estimators.hinf, "Known inputs").
 */
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "lpv.h"

#define HD(c) ((const lpv_hinf_data*)(c)->model->data)

typedef struct {
    size_t design, path, fixed;
} cfg_layout;
typedef struct {
    size_t alpha, work, mats, pmats, yw, zf, a, b, lu, rhs;
} tmp_layout;

static cfg_layout cfg_of(const lpv_hinf_data* d) {
    cfg_layout l;
    l.design = 0;
    l.path = l.design + (size_t)d->design.n_terms * d->design.width;
    l.fixed = l.path + (size_t)d->path.n_terms * d->path.width;
    return l;
}

static tmp_layout tmp_of(const lpv_hinf_data* d) {
    tmp_layout l;
    int big = d->nx > d->ny ? d->nx : d->ny;
    if (d->nz > big) big = d->nz;
    if (d->npx > big) big = d->npx;
    l.alpha = 0;
    l.work = l.alpha + (size_t)d->n_vertices + 1;
    l.mats = l.work + (size_t)d->map.n_formulas + 1;
    l.pmats = l.mats + (size_t)d->design.width;
    l.yw = l.pmats + (size_t)d->path.width + 1;
    l.zf = l.yw + (size_t)d->ny;
    l.a = l.zf + (size_t)d->nz;
    l.b = l.a + (size_t)big;
    l.lu = l.b + (size_t)big;
    l.rhs = l.lu + (size_t)d->nx * d->nx;
    return l;
}

static int sizes(const lpv_model* m, const lpv_values* v, const double* mp, lpv_sizes* out, lpv_msg* err) {
    (void)v, (void)mp, (void)err;
    const lpv_hinf_data* d = (const lpv_hinf_data*)m->data;
    cfg_layout c = cfg_of(d);
    tmp_layout t = tmp_of(d);
    out->n_cfg = c.fixed + (size_t)d->path.width + 1;
    out->n_st = (size_t)d->nx + (size_t)d->npx + 1;
    out->n_words = 0;
    out->n_tmp = t.rhs + (size_t)d->nx + (size_t)d->nu + 1;
    out->n_itmp = (size_t)d->nx + 1;
    return 0;
}

static int configure(lpv_comp* c, const lpv_values* v, const double* mp, lpv_msg* err) {
    (void)v, (void)mp, (void)err;
    const lpv_hinf_data* d = HD(c);
    cfg_layout l = cfg_of(d);
    memcpy(c->cfg + l.design, d->design.rows, sizeof(double) * (size_t)d->design.n_terms * d->design.width);
    if (d->has_u) {
        memcpy(c->cfg + l.path, d->path.rows, sizeof(double) * (size_t)d->path.n_terms * d->path.width);
        if (!d->path_varies) { /* the path at the first vertex, weights [1, 0, ...] (_InputPath) */
            double* e = c->tmp; /* scratch before the first evaluation */
            for (int i = 0; i < d->n_vertices; i++) e[i] = i == 0 ? 1.0 : 0.0;
            lpv_stack_at(&d->path, c->cfg + l.path, e, c->cfg + l.fixed);
        }
    }
    return 0;
}

static void reset(lpv_comp* c, double t0) {
    (void)t0;
    const lpv_hinf_data* d = HD(c);
    for (size_t i = 0; i < c->n_st; i++) c->st[i] = 0.0;
    (void)d;
}

static int check(lpv_comp* c, const double* in, lpv_msg* err) {
    const lpv_hinf_data* d = HD(c);
    if (d->needs_alpha && d->map.kind == LPV_MAP_NONE) /* an alpha input: each weight in [0, 1] does not make a sum of 1 */
        return lpv_check_simplex(in + d->in_sched, d->n_vertices, "alpha", err);
    return 0;
}

static void two(int rows, int n1, const double* M, const double* x, int n2, const double* N, const double* y,
                double* out, double* work) {
    lpv_matvec(rows, n1, M, x, out);
    lpv_matvec(rows, n2, N, y, work);
    for (int i = 0; i < rows; i++) out[i] = out[i] + work[i];
}

static int evaluate(lpv_comp* c, const double* in, double* out, lpv_msg* err) {
    (void)err;
    const lpv_hinf_data* d = HD(c);
    cfg_layout l = cfg_of(d);
    tmp_layout t = tmp_of(d);
    double* alpha = c->tmp + t.alpha;
    if (d->needs_alpha) {
        if (d->map.kind == LPV_MAP_NONE) memcpy(alpha, in + d->in_sched, sizeof(double) * (size_t)d->n_vertices);
        else lpv_map_eval(&d->map, in + d->in_sched, alpha, c->tmp + t.work);
    }
    double* mats = c->tmp + t.mats;
    if (d->scheduled) lpv_stack_at(&d->design, c->cfg + l.design, alpha, mats);
    else memcpy(mats, c->cfg + l.design, sizeof(double) * (size_t)d->design.width);
    const double* xf = c->st;
    const double* y = in + d->in_y;
    double* zhat = out + d->out_zhat;
    double* wa = c->tmp + t.a;
    const int* F = d->fmat;
    if (!d->has_u) {
        two(d->nz, d->nx, mats + F[LPV_HF_CF], xf, d->ny, mats + F[LPV_HF_DF], y, zhat, wa);
        memcpy(c->tmp + t.yw, y, sizeof(double) * (size_t)d->ny);
    } else {
        double* pm = c->tmp + t.pmats;
        if (d->path_varies) lpv_stack_at(&d->path, c->cfg + l.path, alpha, pm);
        else memcpy(pm, c->cfg + l.fixed, sizeof(double) * (size_t)d->path.width);
        const int* P = d->pmat;
        const double* xu = c->st + d->nx;
        const double* u = in + d->in_u;
        double* yw = c->tmp + t.yw;
        /* y - Cy x_u - Dyu u */
        lpv_matvec(d->ny, d->npx, pm + P[LPV_HU_CY], xu, wa);
        for (int i = 0; i < d->ny; i++) yw[i] = y[i] - wa[i];
        lpv_matvec(d->ny, d->nu, pm + P[LPV_HU_DYU], u, wa);
        for (int i = 0; i < d->ny; i++) yw[i] = yw[i] - wa[i];
        double* zf = c->tmp + t.zf;
        two(d->nz, d->nx, mats + F[LPV_HF_CF], xf, d->ny, mats + F[LPV_HF_DF], yw, zf, wa);
        /* Cz x_u + Dzu u + z_f */
        two(d->nz, d->npx, pm + P[LPV_HU_CZ], xu, d->nu, pm + P[LPV_HU_DZU], u, zhat, wa);
        for (int i = 0; i < d->nz; i++) zhat[i] = zhat[i] + zf[i];
        memcpy(c->tmp + t.rhs + d->nx, u, sizeof(double) * (size_t)d->nu); /* u, kept for the step */
    }
    memcpy(out + d->out_xf, xf, sizeof(double) * (size_t)d->nx);
    return 0;
}

static void alpha_text(const lpv_hinf_data* d, const double* alpha, char* buf, size_t size) {
    if (!d->scheduled) {
        snprintf(buf, size, "None");
        return;
    }
    size_t pos = 0;
    buf[pos++] = '[';
    for (int i = 0; i < d->n_vertices && pos + 40 < size; i++) {
        char a[48];
        lpv_fmt_g(a, alpha[i], 8);
        pos += (size_t)snprintf(buf + pos, size - pos, "%s%s", i ? " " : "", a);
    }
    snprintf(buf + pos, size - pos, "]");
}

static int commit(lpv_comp* c, double t_end, lpv_msg* err) {
    (void)t_end;
    const lpv_hinf_data* d = HD(c);
    tmp_layout t = tmp_of(d);
    const double* mats = c->tmp + t.mats;
    const double* alpha = c->tmp + t.alpha;
    const int* F = d->fmat;
    const int n = d->nx;
    double* rhs = c->tmp + t.rhs;
    double* lu = c->tmp + t.lu;
    /* solve H x_{f,k+1} = A_f x_f + B_f y */
    two(n, n, mats + F[LPV_HF_AF], c->st, d->ny, mats + F[LPV_HF_BF], c->tmp + t.yw, rhs, c->tmp + t.a);
    memcpy(lu, mats + F[LPV_HF_H], sizeof(double) * (size_t)n * n);
    char a[512];
    if (lpv_lu_solve(n, lu, c->itmp, rhs, 1)) {
        alpha_text(d, alpha, a, sizeof a);
        lpv_msgf(err, "NumericalError: H(alpha) is singular at alpha = %s: Singular matrix", a);
        return 1;
    }
    for (int i = 0; i < n; i++)
        if (!isfinite(rhs[i])) {
            alpha_text(d, alpha, a, sizeof a);
            lpv_msgf(err, "NumericalError: the filter state became non-finite at alpha = %s", a);
            return 1;
        }
    if (d->has_u) { /* x_u+ = A x_u + Bu u */
        const double* pm = c->tmp + t.pmats;
        const int* P = d->pmat;
        double* xu = c->st + n;
        double* nxt = c->tmp + t.b;
        two(d->npx, d->npx, pm + P[LPV_HU_A], xu, d->nu, pm + P[LPV_HU_BU], rhs + n, nxt, c->tmp + t.a);
        memcpy(xu, nxt, sizeof(double) * (size_t)d->npx);
    }
    memcpy(c->st, rhs, sizeof(double) * (size_t)n);
    c->st[n + d->npx] += 1.0;
    return 0;
}

static const lpv_role ROLE = {sizes, configure, reset, check, evaluate, commit, NULL};

const lpv_role* lpv_role_hinf(void) { return &ROLE; }
