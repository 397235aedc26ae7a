/* Plain C reference of linknet's right-hand side for a chain with one anchored end (issue 6).
 *
 * Masses k = 0..n (mass 0 anchored: inv_m[0] = 0), links l = 0..n-1 joining k1 = l and k2 = l+1.
 * Equation numbers refer to the seed (shared/seeds/000_ae42c96e03439fa9.txt):
 *   E_l = (X_{l+1} - X_l) / R_l                                              (8)
 *   F_k = M_k g on free masses (gravity only)                                 (4)
 *   A T = B, A tridiagonal for a chain:                                       (25)
 *     A_ll     = |E_l|^2 (1/M_l + 1/M_{l+1})      (18; |E_l| = 1 on the manifold)
 *     A_l-1,l  = S/M (E_{l-1} . E_l) = -(E_{l-1} . E_l) / M_l   (21)-(22): k2(l-1) = k1(l), S = (-1)^(2+1)
 *     B_l      = |U_{l+1} - U_l|^2 / R_l + E_l . (F_{l+1}/M_{l+1} - F_l/M_l)   (26)
 *   solved by Thomas' elimination (LDL^T of a tridiagonal matrix), then
 *   dU_k/dt = (F_k + T_k E_k - T_{k-1} E_{k-1}) / M_k                          (9)
 * Arrays are row-major (n+1) x 3 for X, U, acc; work arrays of length n (E: n x 3).
 * Built by benchmarks/bench_kernel.py with the system C compiler (cc -O2 -shared -fPIC).
 */
#include <stddef.h>

void chain_rhs(int n, const double *X, const double *U, const double *R, const double *mass, const double *inv_m,
               const double *g, double *acc, double *T, double *E, double *F, double *diag, double *off)
{
    int k, l;
    /* external forces: gravity on the free masses */
    for (k = 0; k <= n; k++) {
        double m = inv_m[k] > 0.0 ? mass[k] : 0.0;
        F[3 * k] = m * g[0];
        F[3 * k + 1] = m * g[1];
        F[3 * k + 2] = m * g[2];
    }
    /* unit vectors, tridiagonal A and right-hand side B (kept in T) */
    for (l = 0; l < n; l++) {
        const double *xa = X + 3 * l, *xb = X + 3 * (l + 1);
        const double *ua = U + 3 * l, *ub = U + 3 * (l + 1);
        const double *fa = F + 3 * l, *fb = F + 3 * (l + 1);
        double *e = E + 3 * l;
        double ia = inv_m[l], ib = inv_m[l + 1];
        double du0 = ub[0] - ua[0], du1 = ub[1] - ua[1], du2 = ub[2] - ua[2];
        e[0] = (xb[0] - xa[0]) / R[l];
        e[1] = (xb[1] - xa[1]) / R[l];
        e[2] = (xb[2] - xa[2]) / R[l];
        diag[l] = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]) * (ia + ib);
        off[l] = l > 0 ? -(e[0] * e[-3] + e[1] * e[-2] + e[2] * e[-1]) * ia : 0.0;
        T[l] = (du0 * du0 + du1 * du1 + du2 * du2) / R[l]
               + e[0] * (fb[0] * ib - fa[0] * ia) + e[1] * (fb[1] * ib - fa[1] * ia) + e[2] * (fb[2] * ib - fa[2] * ia);
    }
    /* Thomas: forward elimination (diag becomes the pivots), back substitution */
    for (l = 1; l < n; l++) {
        double m = off[l] / diag[l - 1];
        diag[l] -= m * off[l];
        T[l] -= m * T[l - 1];
    }
    T[n - 1] /= diag[n - 1];
    for (l = n - 2; l >= 0; l--)
        T[l] = (T[l] - off[l + 1] * T[l + 1]) / diag[l];
    /* accelerations (9): link l pulls k1 = l by +T_l E_l and k2 = l+1 by -T_l E_l */
    for (k = 0; k <= n; k++) {
        double f0 = F[3 * k], f1 = F[3 * k + 1], f2 = F[3 * k + 2];
        if (k < n) {
            f0 += T[k] * E[3 * k];
            f1 += T[k] * E[3 * k + 1];
            f2 += T[k] * E[3 * k + 2];
        }
        if (k > 0) {
            f0 -= T[k - 1] * E[3 * (k - 1)];
            f1 -= T[k - 1] * E[3 * (k - 1) + 1];
            f2 -= T[k - 1] * E[3 * (k - 1) + 2];
        }
        acc[3 * k] = f0 * inv_m[k];
        acc[3 * k + 1] = f1 * inv_m[k];
        acc[3 * k + 2] = f2 * inv_m[k];
    }
}

/* n_evals evaluations in a row (timed from Python around this one call); returns a checksum so that
 * no evaluation can be optimised away. */
double chain_rhs_repeat(long n_evals, int n, const double *X, const double *U, const double *R, const double *mass,
                        const double *inv_m, const double *g, double *acc, double *T, double *E, double *F,
                        double *diag, double *off)
{
    double checksum = 0.0;
    long i;
    for (i = 0; i < n_evals; i++) {
        chain_rhs(n, X, U, R, mass, inv_m, g, acc, T, E, F, diag, off);
        checksum += acc[3 * n + 2];
    }
    return checksum;
}
