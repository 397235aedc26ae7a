/* The same chain right-hand side as chain_rhs.c, written for speed the way linknet's chain path is: reciprocals
 * of the link lengths instead of divisions, and the unit vectors, A's entries, B, the pivots and the forward
 * substitution in one sweep, the back substitution in a second (the elimination's dependency chain then sets
 * the pace and the rest of the arithmetic fits in its shadow). Same arrays and calling convention as
 * chain_rhs.c; equation numbers as there. A second reference for bench_kernel: what hand-written C reaches.
 */
#include <stddef.h>

void chain_rhs(int n, const double *X, const double *U, const double *R, const double *mass, const double *inv_m,
               const double *g, double *acc, double *T, double *E, double *F, double *dinv, double *sub)
{
    int k, l;
    double w_prev = 0.0, dinv_prev = 0.0, x = 0.0;
    for (k = 0; k <= n; k++) {                                  /* gravity on the free masses */
        double m = inv_m[k] > 0.0 ? mass[k] : 0.0;
        F[3 * k] = m * g[0];
        F[3 * k + 1] = m * g[1];
        F[3 * k + 2] = m * g[2];
    }
    for (l = 0; l < n; l++) {                                   /* (8), (25), (26), LDL^T and forward substitution */
        const double *xa = X + 3 * l, *xb = X + 3 * (l + 1);
        const double *ua = U + 3 * l, *ub = U + 3 * (l + 1);
        const double *fa = F + 3 * l, *fb = F + 3 * (l + 1);
        double *e = E + 3 * l;
        double ia = inv_m[l], ib = inv_m[l + 1], r = 1.0 / R[l];
        double du0 = ub[0] - ua[0], du1 = ub[1] - ua[1], du2 = ub[2] - ua[2];
        double d, b;
        e[0] = (xb[0] - xa[0]) * r;
        e[1] = (xb[1] - xa[1]) * r;
        e[2] = (xb[2] - xa[2]) * r;
        d = (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]) * (ia + ib);
        b = (du0 * du0 + du1 * du1 + du2 * du2) * r
            + e[0] * (fb[0] * ib - fa[0] * ia) + e[1] * (fb[1] * ib - fa[1] * ia) + e[2] * (fb[2] * ib - fa[2] * ia);
        if (l > 0) {
            double off = -(e[0] * e[-3] + e[1] * e[-2] + e[2] * e[-1]) * ia;
            double m = off * dinv_prev;
            sub[l] = m;
            d -= m * off;
            b -= m * w_prev;
        }
        dinv_prev = 1.0 / d;
        dinv[l] = dinv_prev;
        T[l] = b;
        w_prev = b;
    }
    for (l = n - 1; l >= 0; l--) {                              /* back substitution */
        x = (l == n - 1) ? T[l] * dinv[l] : T[l] * dinv[l] - sub[l + 1] * x;
        T[l] = x;
    }
    for (k = 0; k <= n; k++) {                                  /* accelerations (9) */
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

double chain_rhs_repeat(long n_evals, int n, const double *X, const double *U, const double *R, const double *mass,
                        const double *inv_m, const double *g, double *acc, double *T, double *E, double *F,
                        double *dinv, double *sub)
{
    double checksum = 0.0;
    long i;
    for (i = 0; i < n_evals; i++) {
        chain_rhs(n, X, U, R, mass, inv_m, g, acc, T, E, F, dinv, sub);
        checksum += acc[3 * n + 2];
    }
    return checksum;
}
