/*
 * lpvest native runtime: the model data an FMU is generated with (model_data.c)
 * and the interface between the FMI layer (lpv_fmi2.c) and the roles.
 *
 * One runtime serves every FMU. What differs between FMUs is data: the
 * exporter (lpvest/fmi/native/_export.py) writes one model_data.c per FMU that
 * defines `const lpv_model lpv_model_data`: the FMI variables (the same as the
 * Python FMU of the role: names, kinds, ranges, start values), the ports, the
 * parameters, and the role's numbers (hex-float constants) and formulas
 * (stack code, lpv_core.h). Nothing is read from files at run time.
 *
 * Memory: an instance allocates when it is created, configured (fmi2ExitInitializationMode,
 * or a preview of the outputs before it) or restored, with the C library's malloc (the
 * host's allocateMemory is not used); never in fmi2DoStep, fmi2GetReal or fmi2SetReal.
 */
#ifndef LPV_H
#define LPV_H

#include "lpv_core.h"

/* ------------------------------------------------------------ messages */

/* The longest message (characters), as lpvest.fmi.slave.MAX_MESSAGE; a longer
 * one is cut, saying how much was cut. */
#define LPV_MAX_MESSAGE 1000
#define LPV_MSG 1200 /* buffer size of one message (with its prefix) */
#define LPV_MAX_MODEL_PARAMS 64 /* model parameters an instance holds (MAX_MODEL_PARAMS in _export.py) */

typedef struct {
    char text[LPV_MSG];
} lpv_msg;

/* printf into a message (truncated safely) */
void lpv_msgf(lpv_msg* m, const char* fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;
/* append printf text */
void lpv_msg_append(lpv_msg* m, const char* fmt, ...)
#if defined(__GNUC__)
    __attribute__((format(printf, 2, 3)))
#endif
    ;

/* Numbers as Python writes them (the Python FMU's messages), into buf (>= 40 chars):
 * repr(float(v)); the same without a trailing ".0" (lpvest.fmi.slave._num);
 * format(v, "g") with `prec` significant digits (prec >= 1). */
char* lpv_repr(char* buf, double v);
char* lpv_num(char* buf, double v);
char* lpv_fmt_g(char* buf, double v, int prec);
/* lpvest's abbreviate(text, limit) (lpvest/core/_errors.py) of the len bytes of UTF-8 at text:
   Python's repr, cut in the middle when longer than limit, into out (size bytes; 320 hold any
   limit up to 40). Exact but for unassigned code points, which Python escapes and this shows. */
LPV_API void lpv_abbreviate(char* out, size_t size, const char* text, size_t len, int limit);
/* a list of floats as Python writes it: "[0.5, -1.0]" (buf >= 40 n + 3 chars) */
char* lpv_repr_list(char* buf, size_t size, const double* v, int n);
/* parse a decimal number as Python's float() does for ordinary text (sign, digits,
 * point, exponent, underscores between digits, inf, nan); returns 1 if the whole
 * string (after trimming blanks) is one number */
int lpv_parse_float(const char* s, size_t len, double* out);

/* ----------------------------------------------------------- variables */

enum { LPV_PARAMETER = 0, LPV_INPUT = 1, LPV_OUTPUT = 2 };
enum { LPV_REAL = 0, LPV_INTEGER = 1, LPV_BOOLEAN = 2, LPV_STRING = 3 };

/* One FMI scalar variable; its value reference is its index in lpv_model.vars. */
typedef struct {
    const char* name; /* "p[1]" */
    const char* what; /* "input p[1] (theta)": how messages name it */
    int kind;         /* LPV_PARAMETER, LPV_INPUT, LPV_OUTPUT */
    int type;         /* LPV_REAL, ... */
    int owner;        /* its parameter or port (index) */
    int slot;         /* parameters: position in the typed value array; ports: in the flat inputs/outputs */
    int has_min, has_max;
    double min, max; /* declared range */
    double tol;      /* an input's accepted excess over its range (lpvest.validation.check_box) */
} lpv_var;

/* An FMU parameter (a scalar or a vector of Reals). */
typedef struct {
    const char* name;
    int type;
    int size; /* elements */
    int slot; /* first element in its typed value array */
    const double* start_real;
    int start_int; /* Integer and Boolean */
    const char* start_string;
} lpv_param;

/* A port: consecutive elements of the flat inputs or outputs. */
typedef struct {
    const char* name;
    int size;
    int offset;
    int direct; /* outputs: depends on the inputs at the same instant (holds after a step) */
    int late;   /* inputs: a measurement that may arrive late (measurement_delay) */
} lpv_port;

/* The roles (lpv_plant.c, lpv_signal.c, lpv_kalman.c, lpv_hinf.c). */
enum {
    LPV_ROLE_PLANT = 1,
    LPV_ROLE_SCHEDULER = 2,
    LPV_ROLE_SOURCE = 3,
    LPV_ROLE_KALMAN = 4,
    LPV_ROLE_TRUNCATED = 5,
    LPV_ROLE_HINF = 6
};

/* A matrix-valued entry that is a formula of the model parameters: target[index] = f(parameters). */
typedef struct {
    int array; /* which of the role's arrays (role-specific numbering) */
    int index; /* element */
    lpv_formula f;
} lpv_entry;

typedef struct lpv_model {
    const char* identifier;
    const char* guid;
    const char* version; /* lpvest's version */
    int role;
    int n_vars;
    const lpv_var* vars;
    int n_params;
    const lpv_param* params;
    int n_real, n_int, n_bool, n_string; /* parameter elements of each type */
    int n_in_ports;
    const lpv_port* in_ports;
    int n_inputs;
    int n_out_ports;
    const lpv_port* out_ports;
    int n_outputs;
    int timed;               /* a function of time (Scheduler, Source): any step, time kept by the component */
    int sample_time;         /* real slot of the parameter sample_time, or -1 */
    int measurement_delay;   /* integer slot of the parameter measurement_delay, or -1 */
    int n_model_params;      /* the model file's parameters that are FMU parameters */
    const int* model_params; /* their real slots, in the order formulas name them */
    int n_entries;           /* entries that are formulas of the model parameters */
    const lpv_entry* entries;
    const void* data; /* the role's data */
} lpv_model;

/* ------------------------------------------------------------- components */

/* What a configured component owns (one allocation, `mem`), and its state. The
 * state (st: doubles, words: 64-bit words of random generators) is what an FMU
 * state saves; cfg is computed from the parameters; tmp is scratch (pending
 * results of the last evaluation). */
typedef struct lpv_comp {
    const lpv_model* model;
    void* mem;
    double* cfg;
    size_t n_cfg;
    double* st;
    size_t n_st;
    uint64_t* words;
    size_t n_words;
    double* tmp;
    size_t n_tmp;
    int* itmp; /* integer scratch (pivots) */
    size_t n_itmp;
    double t;             /* timed components: the current time */
    double values[8];     /* role-specific scalars fixed at configuration (sizes, flags) */
    const void* role_ctx; /* unused by the FMI layer */
} lpv_comp;

/* The parameter values an instance holds (typed arrays, lpv_param.slot). */
typedef struct {
    const double* reals;
    const int* ints;
    const int* bools;
    const char* const* strings;
} lpv_values;

/* Sizes a role needs for given parameter values. */
typedef struct {
    size_t n_cfg, n_st, n_words, n_tmp, n_itmp;
} lpv_sizes;

/* A role: its functions, called by the FMI layer. Every function returns 0, or
 * nonzero with a message in *err ("TypeName: text", as the Python exception
 * lpvest's slave logs). */
typedef struct lpv_role {
    /* the sizes for these parameters, after checking them (a bad parameter: the
     * message of the Python component's constructor) */
    int (*sizes)(const lpv_model* m, const lpv_values* v, const double* model_params, lpv_sizes* out, lpv_msg* err);
    /* fill cfg from the parameters (called on allocated memory) */
    int (*configure)(lpv_comp* c, const lpv_values* v, const double* model_params, lpv_msg* err);
    /* back to the initial state at time t0 */
    void (*reset)(lpv_comp* c, double t0);
    /* the checks a sample's inputs get beyond their declared ranges (a simplex sum) */
    int (*check)(lpv_comp* c, const double* in, lpv_msg* err);
    /* the outputs at the current sample for these (checked) inputs, no state change;
     * what the step needs is kept in tmp */
    int (*evaluate)(lpv_comp* c, const double* in, double* out, lpv_msg* err);
    /* advance with what evaluate kept (timed components: to t_end) */
    int (*commit)(lpv_comp* c, double t_end, lpv_msg* err);
    /* a restored state (an FMU state from the host): the counters and indices the
     * role computes with are in range (NULL: nothing beyond the FMI layer's checks) */
    int (*check_state)(const lpv_comp* c, lpv_msg* err);
} lpv_role;

/* the roles */
const lpv_role* lpv_role_plant(void);
const lpv_role* lpv_role_scheduler(void);
const lpv_role* lpv_role_source(void);
const lpv_role* lpv_role_kalman(void);
const lpv_role* lpv_role_truncated(void);
const lpv_role* lpv_role_hinf(void);

/* helpers for roles */
int lpv_param_index(const lpv_model* m, const char* name); /* -1 when absent */
const double* lpv_param_reals(const lpv_model* m, const lpv_values* v, const char* name);
int lpv_param_int(const lpv_model* m, const lpv_values* v, const char* name, int fallback);
int lpv_param_bool(const lpv_model* m, const lpv_values* v, const char* name, int fallback);
const char* lpv_param_string(const lpv_model* m, const lpv_values* v, const char* name);
/* evaluate the model-parameter entries of array `array` into `target` */
void lpv_apply_entries(const lpv_model* m, int array, const double* model_params, double* target);
/* a lower triangular factor's inverse check etc. live in lpv_core.h */

/* ---------------------------------------------------------- role data */

/* Matrices side by side: row i of a stack is the i-th term (a vertex, or the
 * coefficient of basis function i), the matrices flattened row-major within it
 * (lpvest._linalg.MatrixStack); `at` weighs the rows as MatrixStack.at does. */
typedef struct {
    int n_terms;
    int width;
    const double* rows; /* n_terms x width */
} lpv_stack;

/* acc = c[0] rows[0] + c[1] rows[1] + ... (elementwise, in this order) */
void lpv_stack_at(const lpv_stack* s, const double* rows, const double* c, double* out);

/* A map from the scheduling p to weights: the formulas of a FormulaSimplexMap
 * (alpha_i = f_i(p)), or the multilinear weights of a MultilinearSimplexMap over
 * coordinates c_j(p) (basis functions) in the box [lower, upper]. */
enum { LPV_MAP_NONE = 0, LPV_MAP_FORMULAS = 1, LPV_MAP_MULTILINEAR = 2 };
typedef struct {
    int kind;
    int n_out;      /* weights */
    int n_formulas; /* formulas (LPV_MAP_FORMULAS: n_out; multilinear: coordinates) */
    const lpv_formula* formulas;
    const double* lower;
    const double* upper;
} lpv_map;

/* the weights at p (work: n_formulas doubles) */
void lpv_map_eval(const lpv_map* map, const double* p, double* out, double* work);
/* [1, psi_1(p), ..., psi_k(p)] of an affine dependence: basis formulas of p */
void lpv_basis_eval(int k, const lpv_formula* basis, const double* p, double* psi);

/* the simplex check of lpvest.validation.check_simplex (an alpha input): 0 or
 * nonzero with the message ("SchedulingRangeError: ...") */
int lpv_check_simplex(const double* alpha, int n, const char* name, lpv_msg* err);

/* lpvest.validation.check_positive_definite (with its symmetry check): 0, or
 * nonzero with the library's message; sym_out (n x n, may be NULL) receives the
 * symmetrised matrix (M + M^T) / 2 the library returns */
int lpv_check_psd(const double* M, int n, const char* name, int semidefinite, double* sym_out, lpv_msg* err);

/* Plant (lpvest.systems.streaming.DiscretePlant) */
enum { LPV_PLANT_POLYTOPIC = 0, LPV_PLANT_AFFINE = 1, LPV_PLANT_INNOVATION = 2, LPV_PLANT_IO = 3 };
/* matrix offsets within a stack row: polytopic A, Bw, Cz, Dz, Cy, Dy, Bu, Dzu, Dyu;
 * affine and innovation A, B, C, D, G, H (-1: absent) */
enum { LPV_PM_A = 0, LPV_PM_BW, LPV_PM_CZ, LPV_PM_DZ, LPV_PM_CY, LPV_PM_DY, LPV_PM_BU, LPV_PM_DZU, LPV_PM_DYU };
enum { LPV_AM_A = 0, LPV_AM_B, LPV_AM_C, LPV_AM_D, LPV_AM_G, LPV_AM_H };
typedef struct {
    int kind;
    int nx, nu, ny, nz, nw, nv;
    int n_p; /* scheduling components (0: a polytopic model scheduled by alpha) */
    lpv_stack stack; /* model-parameter entries: array 0 */
    int mat[9];
    lpv_map map;                /* polytopic: p -> alpha */
    int n_basis;                /* affine, innovation: basis functions of p */
    const lpv_formula* basis;
    int n_noise;                /* the noise drawn per sample: [w; v] (affine), e (innovation) */
    const double* chol;         /* its covariance's lower Cholesky factor */
    const lpv_formula* K;       /* innovation: the gain, nx x ny formulas of p; input-output: the
                                   coefficients a (of y), b (of u), c (of e), formulas of p */
    const char* const* K_text;  /* their text (messages) */
    int io_n[3];                /* input-output: the numbers of a, b and c (the state: past y, u, e) */
    int in_p, in_alpha, in_u, in_w, in_v, in_e; /* input offsets (-1: absent) */
    int out_y, out_z, out_x;
} lpv_plant_data;

/* Scheduler and Source signals (lpvest.signals) */
typedef struct {
    const char* name;   /* "p", "u", "w" */
    const char* prefix; /* of its parameters: "" (Scheduler), "u." , "w." */
    int n;
    int out;            /* output offset */
} lpv_signal_def;

typedef struct {
    int n_p;
    const double* lower; /* the scheduling box */
    const double* upper;
    const char* const* names;
    lpv_map map; /* p -> alpha of a polytopic model (kind NONE: no alpha output) */
    int out_p, out_alpha;
} lpv_scheduler_data;

typedef struct {
    int n_signals;
    const lpv_signal_def* signals;
} lpv_source_data;

/* Kalman and TruncatedKalman (lpvest.estimators.kalman, lpvest.estimators.truncated) */
typedef struct {
    int nx, nu, ny, n_p;
    int n_basis;
    const lpv_formula* basis;
    int n_z;              /* 1 + k + k (k + 1) / 2 */
    const int* pairs;     /* (i, j), 1-based, of the products psi_i psi_j in z */
    int f_rows, f_cols;   /* the packed matrix F of one sample */
    const double* packed; /* n_z x f_rows f_cols; model-parameter entries: array 0 */
    int in_p, in_u, in_y;
    int out_xhat, out_P, out_xpred, out_Ppred, out_yhat, out_innovation, out_K, out_Omega, out_loglik;
    const double* x0;             /* the model's x0 and P0 (the TruncatedKalman FMU has no such parameters) */
    const double* P0;
    const double* theorem_start;  /* TruncatedKalman: P^_0 of start = "theorem" (NULL: not available) */
    const char* theorem_error;    /* why not (the library's message) */
    const double* box_lower;      /* the scheduling box (start_p) */
    const double* box_upper;
    const char* const* names;
} lpv_kalman_data;

/* HinfPD and HinfRobust (lpvest.estimators.hinf) */
enum { LPV_HF_H = 0, LPV_HF_AF, LPV_HF_BF, LPV_HF_CF, LPV_HF_DF };
enum { LPV_HU_A = 0, LPV_HU_CZ, LPV_HU_CY, LPV_HU_BU, LPV_HU_DZU, LPV_HU_DYU };
typedef struct {
    int nx, ny, nz;
    int scheduled;      /* the design's gains depend on alpha */
    int n_vertices;     /* of the design (and the plant) */
    lpv_stack design;   /* its vertex matrices (1 row for a robust design) */
    int fmat[5];
    int needs_alpha;    /* a scheduling input (scheduled, or a varying input path) */
    lpv_map map;        /* p -> alpha when the scheduling input is p (kind NONE: the input is alpha) */
    int has_u, nu, npx; /* a known input compensated: its size and the plant's state size */
    int path_varies;
    lpv_stack path;     /* the plant's A, Cz, Cy, Bu, Dzu, Dyu at its vertices */
    int pmat[6];
    int in_sched, in_u, in_y;
    int out_zhat, out_xf;
} lpv_hinf_data;

/* the model this FMU was generated with (model_data.c) */
extern const lpv_model lpv_model_data;

#endif /* LPV_H */
