/*
 * lpvest native runtime: the Plant role (lpvest.systems.streaming.DiscretePlant).
 *
 * A polytopic model (Peixoto et al. (1)), an affine model with general noise
 * (Cox & Toth (1)-(3)), an innovation form with a gain of p_t or an input-output
 * model (Cox & Toth (21a)), one sample per step: the outputs y_k (and z_k) at the
 * inputs of sample k, the state x_k; the step x_{k+1}. The input-output model's
 * state is its memory [y_{k-1..k-na}, u_{k-1..k-nb+1}, e_{k-1..k-nc}], and y_k is
 * summed in LPVInputOutput.simulate's order: e_k, the y terms, the u terms, the e
 * terms. The noise of sample k is drawn when the plant arrives at k (at
 * reset and after each step): [w; v] = L z (affine), e = L z (innovation,
 * input-output), z from
 * lpvest's stream (lpv_rng.c), after the initial state x_0 = x0 + L_0 z when the
 * affine model's P0 is not zero (lpvest.rng.Stream.gaussian_vector): the same
 * numbers as the library for the same seed.
 *
 * Parameters: x0, and P0 (affine), noise, seed (affine, innovation, input-output), the model
 * file's parameters (as formulas of its matrix entries, lpv_model.entries).
 */
#include <math.h>
#include <string.h>

#include "lpv.h"

#define PD(c) ((const lpv_plant_data*)(c)->model->data)

/* cfg layout */
typedef struct {
    size_t rows, x0, l0, draw_x0;
} cfg_layout;
/* st layout: x (nx), k (1), noise (n_noise) */
/* tmp layout */
typedef struct {
    size_t mats, weights, work, nxt, a, b, c, z, K, psi;
} tmp_layout;

static cfg_layout cfg_of(const lpv_plant_data* d) {
    cfg_layout l;
    l.rows = 0;
    l.x0 = l.rows + (size_t)d->stack.n_terms * (size_t)d->stack.width;
    l.l0 = l.x0 + (size_t)d->nx;
    l.draw_x0 = l.l0 + (size_t)d->nx * (size_t)d->nx;
    return l;
}

static tmp_layout tmp_of(const lpv_plant_data* d) {
    tmp_layout l;
    size_t big = (size_t)(d->nx > d->ny ? d->nx : d->ny);
    if ((size_t)d->nz > big) big = (size_t)d->nz;
    l.mats = 0;
    l.weights = l.mats + (size_t)d->stack.width;
    l.work = l.weights + (size_t)d->stack.n_terms + 1;
    l.nxt = l.work + (size_t)d->map.n_formulas + 1;
    l.a = l.nxt + (size_t)d->nx;
    l.b = l.a + big;
    l.c = l.b + big;
    l.z = l.c + big;
    l.K = l.z + (size_t)d->n_noise + (size_t)d->nx + 1;
    size_t nK = (size_t)d->nx * (size_t)d->ny;
    size_t n_io = (size_t)(d->io_n[0] + d->io_n[1] + d->io_n[2]);
    l.psi = l.K + (nK > n_io ? nK : n_io);
    return l;
}

static int sizes(const lpv_model* m, const lpv_values* v, const double* mp, lpv_sizes* out, lpv_msg* err) {
    (void)mp;
    const lpv_plant_data* d = (const lpv_plant_data*)m->data;
    cfg_layout c = cfg_of(d);
    tmp_layout t = tmp_of(d);
    out->n_cfg = c.draw_x0 + 1;
    out->n_st = (size_t)d->nx + 1 + (size_t)d->n_noise;
    out->n_words = 4;
    out->n_tmp = t.psi + (size_t)d->n_basis + 1;
    out->n_itmp = 0;
    if (d->kind == LPV_PLANT_AFFINE) { /* P0: symmetric positive semidefinite (check_positive_definite) */
        const double* P0 = lpv_param_reals(m, v, "P0");
        if (!P0) {
            lpv_msgf(err, "LpvestError: this plant has no parameter P0");
            return 1;
        }
        if (lpv_check_psd(P0, d->nx, "P0", 1, NULL, err)) return 1;
    }
    return 0;
}

static int configure(lpv_comp* c, const lpv_values* v, const double* mp, lpv_msg* err) {
    const lpv_model* m = c->model;
    const lpv_plant_data* d = PD(c);
    cfg_layout l = cfg_of(d);
    if (d->stack.n_terms > 0) /* an input-output model has no matrices */
        memcpy(c->cfg + l.rows, d->stack.rows, sizeof(double) * (size_t)d->stack.n_terms * (size_t)d->stack.width);
    lpv_apply_entries(m, 0, mp, c->cfg + l.rows);
    const double* x0 = lpv_param_reals(m, v, "x0");
    if (!x0) {
        lpv_msgf(err, "LpvestError: this plant has no parameter x0");
        return 1;
    }
    memcpy(c->cfg + l.x0, x0, sizeof(double) * (size_t)d->nx);
    int noise = lpv_param_bool(m, v, "noise", 0);
    int seed = lpv_param_int(m, v, "seed", 0);
    c->values[0] = noise;
    c->values[1] = seed;
    c->cfg[l.draw_x0] = 0.0;
    if (d->kind == LPV_PLANT_AFFINE) {
        /* the symmetrised P0 (what check_positive_definite returns), its factor in place */
        const double* P0 = lpv_param_reals(m, v, "P0");
        int n = d->nx, any = 0;
        double* sym = c->tmp; /* scratch before the first evaluation */
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) {
                sym[i * n + j] = 0.5 * P0[i * n + j] + 0.5 * P0[j * n + i];
                any |= sym[i * n + j] != 0.0;
            }
        if (noise && any) {
            lpv_psd_cholesky(n, sym, c->cfg + l.l0);
            c->cfg[l.draw_x0] = 1.0;
        }
    }
    return 0;
}

/* the model noise of the current sample (zeros without noise) */
static void draw(lpv_comp* c) {
    const lpv_plant_data* d = PD(c);
    if (d->n_noise == 0) return;
    double* noise = c->st + d->nx + 1;
    if (!c->values[0]) {
        for (int i = 0; i < d->n_noise; i++) noise[i] = 0.0;
        return;
    }
    tmp_layout t = tmp_of(d);
    double* z = c->tmp + t.z;
    lpv_pcg64* g = (lpv_pcg64*)c->words;
    for (int i = 0; i < d->n_noise; i++) z[i] = lpv_normal(g);
    lpv_lower_times(d->n_noise, d->chol, z, noise);
}

static void reset(lpv_comp* c, double t0) {
    (void)t0;
    const lpv_plant_data* d = PD(c);
    cfg_layout l = cfg_of(d);
    uint32_t word = (uint32_t)(int)c->values[1];
    lpv_pcg64_seed((lpv_pcg64*)c->words, &word, 1);
    c->st[d->nx] = 0.0; /* k */
    if (c->cfg[l.draw_x0] != 0.0) {
        tmp_layout t = tmp_of(d);
        double* z = c->tmp + t.z;
        double* lz = c->tmp + t.a;
        for (int i = 0; i < d->nx; i++) z[i] = lpv_normal((lpv_pcg64*)c->words);
        lpv_lower_times(d->nx, c->cfg + l.l0, z, lz);
        for (int i = 0; i < d->nx; i++) c->st[i] = c->cfg[l.x0 + i] + lz[i];
    } else {
        memcpy(c->st, c->cfg + l.x0, sizeof(double) * (size_t)d->nx);
    }
    draw(c);
}

static int check(lpv_comp* c, const double* in, lpv_msg* err) {
    const lpv_plant_data* d = PD(c);
    if (d->kind == LPV_PLANT_POLYTOPIC && d->in_alpha >= 0) /* each weight in [0, 1] does not make a sum of 1 */
        return lpv_check_simplex(in + d->in_alpha, d->stack.n_terms, "alpha", err);
    return 0;
}

/* y = M x + N u (matvecs, then added: numpy's (M @ x) + (N @ u)) */
static void two(int rows, int nx, const double* M, const double* x, int nu, const double* N, const double* u,
                double* y, double* work) {
    lpv_matvec(rows, nx, M, x, y);
    lpv_matvec(rows, nu, N, u, work);
    for (int i = 0; i < rows; i++) y[i] = y[i] + work[i];
}

static void add_matvec(int rows, int n, const double* M, const double* x, double* y, double* work) {
    lpv_matvec(rows, n, M, x, work);
    for (int i = 0; i < rows; i++) y[i] = y[i] + work[i];
}

/* input-output: y_k and the next memory (LPVInputOutput.simulate, one sample) */
static int io_step(lpv_comp* c, const double* x, const double* in, double* out, double* nxt, lpv_msg* err) {
    const lpv_plant_data* d = PD(c);
    tmp_layout t = tmp_of(d);
    const double* p = in + d->in_p;
    int na = d->io_n[0], nb = d->io_n[1], nc = d->io_n[2];
    double* co = c->tmp + t.K; /* a, b, c */
    int bad = 0;
    for (int i = 0; i < na + nb + nc; i++) {
        co[i] = lpv_formula_eval(&d->K[i], p);
        bad |= !isfinite(co[i]);
    }
    if (bad) {
        char list[1024];
        lpv_msgf(err, "ExpressionError: the coefficients are not finite at p = %s",
                 lpv_repr_list(list, sizeof list, p, d->n_p));
        return 1;
    }
    int nu_mem = nb > 1 ? nb - 1 : 0;
    const double* ys = x;
    const double* us = x + na;
    const double* es = x + na + nu_mem;
    const double* noise = c->st + d->nx + 1;
    double u = nb ? in[d->in_u] : 0.0;
    double e = in[d->in_e] + noise[0];
    double acc = e;
    for (int i = 0; i < na; i++) acc = acc + co[i] * ys[i];
    if (nb) acc = acc + co[na] * u;
    for (int i = 1; i < nb; i++) acc = acc + co[na + i] * us[i - 1];
    for (int i = 0; i < nc; i++) acc = acc + co[na + nb + i] * es[i];
    out[d->out_y] = acc;
    /* each memory shifted by one, the newest value first */
    if (na) {
        nxt[0] = acc;
        for (int i = 1; i < na; i++) nxt[i] = ys[i - 1];
    }
    if (nu_mem) {
        nxt[na] = u;
        for (int i = 1; i < nu_mem; i++) nxt[na + i] = us[i - 1];
    }
    if (nc) {
        nxt[na + nu_mem] = e;
        for (int i = 1; i < nc; i++) nxt[na + nu_mem + i] = es[i - 1];
    }
    return 0;
}

static int evaluate(lpv_comp* c, const double* in, double* out, lpv_msg* err) {
    const lpv_plant_data* d = PD(c);
    cfg_layout l = cfg_of(d);
    tmp_layout t = tmp_of(d);
    const double* x = c->st;
    double* mats = c->tmp + t.mats;
    double* weights = c->tmp + t.weights;
    double* nxt = c->tmp + t.nxt;
    double* wa = c->tmp + t.a;
    double* wb = c->tmp + t.b;
    const double* rows = c->cfg + l.rows;
    if (d->kind == LPV_PLANT_POLYTOPIC) {
        if (d->in_alpha >= 0) memcpy(weights, in + d->in_alpha, sizeof(double) * (size_t)d->stack.n_terms);
        else lpv_map_eval(&d->map, in + d->in_p, weights, c->tmp + t.work);
        lpv_stack_at(&d->stack, rows, weights, mats);
        const int* M = d->mat;
        const double* w = in + d->in_w;
        double* y = out + d->out_y;
        double* z = out + d->out_z;
        two(d->ny, d->nx, mats + M[LPV_PM_CY], x, d->nw, mats + M[LPV_PM_DY], w, y, wa);
        two(d->nz, d->nx, mats + M[LPV_PM_CZ], x, d->nw, mats + M[LPV_PM_DZ], w, z, wa);
        two(d->nx, d->nx, mats + M[LPV_PM_A], x, d->nw, mats + M[LPV_PM_BW], w, nxt, wa);
        if (d->in_u >= 0 && M[LPV_PM_BU] >= 0) {
            const double* u = in + d->in_u;
            add_matvec(d->ny, d->nu, mats + M[LPV_PM_DYU], u, y, wa);
            add_matvec(d->nz, d->nu, mats + M[LPV_PM_DZU], u, z, wa);
            add_matvec(d->nx, d->nu, mats + M[LPV_PM_BU], u, nxt, wa);
        }
    } else if (d->kind == LPV_PLANT_IO) {
        if (io_step(c, x, in, out, nxt, err)) return 1;
    } else {
        double* psi = c->tmp + t.psi;
        const double* p = in + d->in_p;
        lpv_basis_eval(d->n_basis, d->basis, p, psi);
        lpv_stack_at(&d->stack, rows, psi, mats);
        const int* M = d->mat;
        const double* noise = c->st + d->nx + 1;
        static const double none = 0.0;
        const double* u = d->in_u >= 0 ? in + d->in_u : &none;
        double* y = out + d->out_y;
        if (d->kind == LPV_PLANT_AFFINE) {
            double* wn = c->tmp + t.z; /* w + noise[:nw], then v + noise[nw:] */
            for (int i = 0; i < d->nw; i++) wn[i] = in[d->in_w + i] + noise[i];
            double* vn = wn + d->nw;
            for (int i = 0; i < d->nv; i++) vn[i] = in[d->in_v + i] + noise[d->nw + i];
            two(d->ny, d->nx, mats + M[LPV_AM_C], x, d->nu, mats + M[LPV_AM_D], u, y, wa);
            add_matvec(d->ny, d->nv, mats + M[LPV_AM_H], vn, y, wa);
            two(d->nx, d->nx, mats + M[LPV_AM_A], x, d->nu, mats + M[LPV_AM_B], u, nxt, wa);
            add_matvec(d->nx, d->nw, mats + M[LPV_AM_G], wn, nxt, wa);
        } else {
            double* K = c->tmp + t.K;
            int bad = 0;
            for (int i = 0; i < d->nx * d->ny; i++) {
                K[i] = lpv_formula_eval(&d->K[i], p);
                bad |= !isfinite(K[i]);
            }
            if (bad) {
                char list[1024];
                lpv_msgf(err, "ExpressionError: the gain K is not finite at p = %s",
                         lpv_repr_list(list, sizeof list, p, d->n_p));
                return 1;
            }
            double* e = c->tmp + t.z;
            for (int i = 0; i < d->ny; i++) e[i] = in[d->in_e + i] + noise[i];
            two(d->ny, d->nx, mats + M[LPV_AM_C], x, d->nu, mats + M[LPV_AM_D], u, y, wa);
            for (int i = 0; i < d->ny; i++) y[i] = y[i] + e[i];
            two(d->nx, d->nx, mats + M[LPV_AM_A], x, d->nu, mats + M[LPV_AM_B], u, nxt, wa);
            add_matvec(d->nx, d->ny, K, e, nxt, wb);
        }
    }
    memcpy(out + d->out_x, x, sizeof(double) * (size_t)d->nx);
    return 0;
}

static int commit(lpv_comp* c, double t_end, lpv_msg* err) {
    (void)t_end, (void)err;
    const lpv_plant_data* d = PD(c);
    tmp_layout t = tmp_of(d);
    memcpy(c->st, c->tmp + t.nxt, sizeof(double) * (size_t)d->nx);
    c->st[d->nx] += 1.0;
    draw(c);
    return 0;
}

static const lpv_role ROLE = {sizes, configure, reset, check, evaluate, commit, NULL};

const lpv_role* lpv_role_plant(void) { return &ROLE; }
