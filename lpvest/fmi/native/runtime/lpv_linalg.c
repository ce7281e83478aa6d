/*
 * lpvest native runtime: small dense kernels (row-major, no allocation).
 *
 * Where the library computes the same quantity in Python floats (the Cholesky
 * factor of a small innovation covariance, its inverse, the semidefinite factor
 * of a covariance drawn from), the loops here are the same operations in the same
 * order, so the results are the same bits. Products the library leaves to numpy
 * (BLAS) are summed here in index order; they agree to rounding, within the bound
 * the tests derive.
 */
#include <math.h>

#include "lpv_core.h"

void lpv_matvec(int m, int n, const double* A, const double* x, double* y) {
    for (int i = 0; i < m; i++) {
        const double* a = A + (size_t)i * n;
        double acc = 0.0;
        if (n > 0) {
            acc = a[0] * x[0];
            for (int j = 1; j < n; j++) acc += a[j] * x[j];
        }
        y[i] = acc;
    }
}

void lpv_matmul(int m, int k, int n, const double* A, const double* B, double* C) {
    for (int i = 0; i < m; i++) {
        const double* a = A + (size_t)i * k;
        for (int j = 0; j < n; j++) {
            double acc = 0.0;
            if (k > 0) {
                acc = a[0] * B[j];
                for (int l = 1; l < k; l++) acc += a[l] * B[(size_t)l * n + j];
            }
            C[(size_t)i * n + j] = acc;
        }
    }
}

void lpv_matmul_bt(int m, int k, int n, const double* A, const double* B, double* C) {
    for (int i = 0; i < m; i++) {
        const double* a = A + (size_t)i * k;
        for (int j = 0; j < n; j++) {
            const double* b = B + (size_t)j * k;
            double acc = 0.0;
            if (k > 0) {
                acc = a[0] * b[0];
                for (int l = 1; l < k; l++) acc += a[l] * b[l];
            }
            C[(size_t)i * n + j] = acc;
        }
    }
}

int lpv_cholesky(int n, const double* A, double* L, double* pivot, double* logdet) {
    double ld = 0.0;
    for (int i = 0; i < n * n; i++) L[i] = 0.0;
    for (int i = 0; i < n; i++) {
        double* Li = L + (size_t)i * n;
        for (int j = 0; j <= i; j++) {
            const double* Lj = L + (size_t)j * n;
            double s = A[(size_t)i * n + j];
            for (int k = 0; k < j; k++) s -= Li[k] * Lj[k];
            if (i == j) {
                if (!(s > 0.0 && s < HUGE_VAL)) {
                    if (pivot) *pivot = s;
                    return i + 1;
                }
                Li[i] = sqrt(s);
                ld += log(s);
            } else {
                Li[j] = s / Lj[j];
            }
        }
    }
    if (logdet) *logdet = ld;
    return 0;
}

void lpv_lower_inverse(int n, const double* L, double* Ci) {
    for (int i = 0; i < n * n; i++) Ci[i] = 0.0;
    for (int c = 0; c < n; c++) {
        for (int i = c; i < n; i++) {
            const double* Li = L + (size_t)i * n;
            double s = i == c ? 1.0 : 0.0;
            for (int k = c; k < i; k++) s -= Li[k] * Ci[(size_t)k * n + c];
            Ci[(size_t)i * n + c] = s / Li[i];
        }
    }
}

int lpv_lu_solve(int n, double* A, int* piv, double* b, int nrhs) {
    for (int k = 0; k < n; k++) {
        int p = k;
        double best = fabs(A[(size_t)k * n + k]);
        for (int i = k + 1; i < n; i++) {
            double v = fabs(A[(size_t)i * n + k]);
            if (v > best) best = v, p = i;
        }
        if (!(best > 0.0 && best < HUGE_VAL)) return 1;
        piv[k] = p;
        if (p != k) {
            for (int j = 0; j < n; j++) {
                double t = A[(size_t)k * n + j];
                A[(size_t)k * n + j] = A[(size_t)p * n + j];
                A[(size_t)p * n + j] = t;
            }
            for (int j = 0; j < nrhs; j++) {
                double t = b[(size_t)k * nrhs + j];
                b[(size_t)k * nrhs + j] = b[(size_t)p * nrhs + j];
                b[(size_t)p * nrhs + j] = t;
            }
        }
        double d = A[(size_t)k * n + k];
        for (int i = k + 1; i < n; i++) {
            double f = A[(size_t)i * n + k] / d;
            A[(size_t)i * n + k] = f;
            for (int j = k + 1; j < n; j++) A[(size_t)i * n + j] -= f * A[(size_t)k * n + j];
            for (int j = 0; j < nrhs; j++) b[(size_t)i * nrhs + j] -= f * b[(size_t)k * nrhs + j];
        }
    }
    for (int j = 0; j < nrhs; j++) {
        for (int i = n - 1; i >= 0; i--) {
            double s = b[(size_t)i * nrhs + j];
            for (int k = i + 1; k < n; k++) s -= A[(size_t)i * n + k] * b[(size_t)k * nrhs + j];
            b[(size_t)i * nrhs + j] = s / A[(size_t)i * n + i];
        }
    }
    return 0;
}

int lpv_sym_eigenvalues(int n, const double* A, double* w, double* work) {
    double* a = work; /* n x n, symmetrised copy; the rest of work is not needed */
    for (int i = 0; i < n; i++)
        for (int j = 0; j < n; j++) a[(size_t)i * n + j] = 0.5 * A[(size_t)i * n + j] + 0.5 * A[(size_t)j * n + i];
    int converged = 0;
    for (int sweep = 0; sweep < 100 && !converged; sweep++) {
        double off = 0.0, total = 0.0;
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) {
                double v = a[(size_t)i * n + j] * a[(size_t)i * n + j];
                total += v;
                if (i != j) off += v;
            }
        if (off <= 1e-36 * total || off == 0.0) {
            converged = 1;
            break;
        }
        for (int p = 0; p < n - 1; p++) {
            for (int q = p + 1; q < n; q++) {
                double apq = a[(size_t)p * n + q];
                if (apq == 0.0) continue;
                double app = a[(size_t)p * n + p], aqq = a[(size_t)q * n + q];
                double theta = (aqq - app) / (2.0 * apq);
                double t = (theta >= 0.0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
                if (!isfinite(t)) t = 0.0; /* theta overflowed: the rotation is the identity to rounding */
                double c = 1.0 / sqrt(t * t + 1.0), s = t * c;
                for (int k = 0; k < n; k++) {
                    double akp = a[(size_t)k * n + p], akq = a[(size_t)k * n + q];
                    a[(size_t)k * n + p] = c * akp - s * akq;
                    a[(size_t)k * n + q] = s * akp + c * akq;
                }
                for (int k = 0; k < n; k++) {
                    double apk = a[(size_t)p * n + k], aqk = a[(size_t)q * n + k];
                    a[(size_t)p * n + k] = c * apk - s * aqk;
                    a[(size_t)q * n + k] = s * apk + c * aqk;
                }
                a[(size_t)p * n + q] = a[(size_t)q * n + p] = 0.0;
            }
        }
    }
    for (int i = 0; i < n; i++) w[i] = a[(size_t)i * n + i];
    for (int i = 1; i < n; i++) { /* insertion sort, ascending */
        double v = w[i];
        int j = i - 1;
        while (j >= 0 && w[j] > v) w[j + 1] = w[j], j--;
        w[j + 1] = v;
    }
    return converged ? 0 : 1;
}

void lpv_psd_cholesky(int n, const double* P, double* L) {
    double scale = 0.0;
    for (int i = 0; i < n; i++)
        if (i == 0 || P[(size_t)i * n + i] > scale) scale = P[(size_t)i * n + i];
    double tol = n * 2.220446049250313e-16 * scale;
    for (int i = 0; i < n * n; i++) L[i] = 0.0;
    for (int j = 0; j < n; j++) {
        double d = P[(size_t)j * n + j];
        for (int k = 0; k < j; k++) d -= L[(size_t)j * n + k] * L[(size_t)j * n + k];
        if (d <= tol) continue; /* a zero pivot: column j stays zero */
        double ljj = sqrt(d);
        L[(size_t)j * n + j] = ljj;
        for (int i = j + 1; i < n; i++) {
            double s = P[(size_t)i * n + j];
            for (int k = 0; k < j; k++) s -= L[(size_t)i * n + k] * L[(size_t)j * n + k];
            L[(size_t)i * n + j] = s / ljj;
        }
    }
}

void lpv_lower_times(int n, const double* L, const double* z, double* out) {
    for (int i = 0; i < n; i++) {
        const double* Li = L + (size_t)i * n;
        double acc = Li[0] * z[0];
        for (int j = 1; j <= i; j++) acc = acc + Li[j] * z[j];
        out[i] = acc;
    }
}
