/* Minimum-norm solves of the tension system (25) where A is singular (declared in stages.h, minnorm.h).
 *
 * A = C M^-1 C^T, row l of C being +E_l at k1(l) and -E_l at k2(l) (anchored masses: 1/M = 0), is
 * symmetric positive semi-definite. Its null space is the set of self-stresses: the homogeneous solutions
 * of (27), which by (28)-(30) are exactly the tensions that put no force on any free mass (31). Given a
 * consistent right-hand side (32)-(36), every solution of A T = B gives the same forces C^T T on the free
 * masses, and the one reported is the minimum-norm solution T = A^+ B: the solution with no component
 * along the self-stresses, the same tensions whichever way the system is solved.
 *
 * Two paths, chosen by the size of the system:
 *
 * Dense (L <= dense_min_norm_limit). Cholesky with complete (diagonal) pivoting, P A P^T = R^T R, stopped
 *   at rank r when every remaining diagonal entry of the Schur complement is below rank_tol times the
 *   largest diagonal entry of A. Those pivots have the scale of the eigenvalues of A, so this is the same
 *   kind of cut as the numpy path's eigenvalue cut at rank_tol relative (1e-10 on the eigenvalues of A is
 *   1e-5 on the singular values of C M^-1/2); on the test scenes the ranks agree. With R = [R11 R12]
 *   (r x L, R11 upper triangular) the null space of P A P^T is spanned by the columns of Z = [-W; I],
 *   W = R11^-1 R12, and
 *       x = Pz(xb),  xb = [R11^-1 R11^-T c_1; 0],  c = Pz(P b),  Pz(y) = y - Z (Z^T Z)^-1 Z^T y.
 *   Projecting b first (c) drops the component of b along the self-stresses, so an inconsistent b (round-off
 *   in (32)) gets A^+ b, the minimum-norm least-squares answer, not a basic solution of part of the rows.
 *   Z^T Z = I + W^T W has all its eigenvalues >= 1, so its (unpivoted) Cholesky factor always exists.
 *   Cost: L^3/3 flops for a regular A; for rank r, about (L^3 - (L-r)^3)/3 for R, r^2 (L-r) for W and
 *   r (L-r)^2 for Z^T Z. A solve is O(L^2) and allocates nothing.
 *   Accuracy: relative error of x about eps * kappa * g, kappa = largest / smallest non-zero eigenvalue of
 *   A and g = (1 + |W|^2) |xb| / |x| the growth of the null-space correction (g = 1 for a regular A).
 *   Complete pivoting gives |R_ij| <= R_ii, which bounds |W| only by 2^r in the worst case (Higham, Accuracy
 *   and Stability of Numerical Algorithms, ch. 10), but self-stresses are local: max |W_ij| is 1.4-1.9 on
 *   trusses and nets with diagonals up to L = 2500. Measured against an exact A^+ B (B = A T, T in
 *   range(A)): 2e-11 at kappa = 1.7e6 (prism truss, L = 300), 5e-10 at kappa = 2e8 (L = 996), where the
 *   eigen-decomposition gives 1e-10 and 4e-9.
 *
 * Iterative (larger L). Conjugate gradients from x = 0, without preconditioner, with the matrix-free
 *   product A x = C M^-1 C^T x (three passes over the links and masses, nothing assembled). The iterates
 *   lie in the Krylov space of (A, b), inside range(A) for a consistent b, so the limit is the
 *   minimum-norm solution. A preconditioner P would lose that: the iterates would lie in P range(A), and
 *   the limit would be the solution of least P^-1-norm instead. Stops when the recursive residual is below
 *   MN_CG_RTOL (1e-14) relative, when p^T A p falls below rank_tol times the largest diagonal entry times
 *   p^T p (p then lies in what the dense path calls the null space, and a step along it would only add a
 *   self-stress), when the residual has not reached a new minimum for as many iterations as it took to
 *   reach the last one (at least MN_CG_STALL_MIN), or after 10 L + 100 iterations. It returns the iterate
 *   of least residual: if b carries a self-stress component above MN_CG_RTOL, CG's residual stops falling
 *   at that level and its later iterates grow along the null space, invisibly to the residual; the
 *   least-residual iterate carries only the multiple of b's null component that every Krylov method from 0
 *   inherits (relative to x, about kappa times b's relative to b). B of (26) is consistent by (32)-(36) up
 *   to round-off, and in the corrections of the projections a self-stress component is harmless: it moves
 *   no mass (31). Accuracy for a consistent b: relative error about eps * kappa, as the dense path
 *   (measured: 1e-10 at kappa = 1.7e6, 1e-8 at kappa = 2e8). The 100 x 100 net with diagonals
 *   (L = 39402) takes about 1200 iterations.
 *
 * The workspace (struct ln_minnorm_work) is independent of DIM and shared by the two copies of this file;
 * it lives in d->minnorm, is allocated or grown by the factorisation and freed by ln_minnorm_free.
 */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "../dim.h"
#include "../linknet.h"
#include "../ln_math.h"
#include "../minnorm.h"
#include "../stages.h"

#ifndef LINKNET_MINNORM_COMMON
#define LINKNET_MINNORM_COMMON

/* Rows per panel of the blocked factorisations: a panel of 64 rows of up to 2500 doubles stays in cache
   while the trailing matrix streams past it once. */
#define MN_PANEL 64
#define MN_CG_RTOL 1e-14
#define MN_CG_STALL_MIN 100
/* Used only when a model leaves rank_tol unset (0): the cut of linknet_core.structure.SINGULAR_RCOND. */
#define MN_DEFAULT_RANK_TOL 1e-10

enum mn_stop { MN_STOP_NONE = 0, MN_STOP_CONVERGED = 1, MN_STOP_NULL_DIRECTION = 2, MN_STOP_STAGNATED = 3,
               MN_STOP_MAX_ITER = 4 };

struct ln_minnorm_work {
    ln_int L, K;                /* lengths the vectors below were allocated for */
    size_t dense_capacity;      /* doubles in a */
    int dense;                  /* path of the last factorisation */
    int usable;                 /* the last factorisation succeeded with a finite E (else solves give NaN) */
    ln_int rank;                /* dense: numerical rank r of A; iterative: -1 */

    /* dense: rows 0..r-1 of a hold R11 R12 (upper part, row-major, leading dimension L) and, after the
       factorisation, W = R11^-1 R12 in place of R12; the block a[r.., r..] holds the upper Cholesky
       factor S of Z^T Z = I + W^T W. perm: pivoted position -> link. */
    double *a;
    ln_int *perm;
    double *diag;               /* (L) Schur-complement diagonal while factoring */
    double *c, *t;              /* (L) solve scratch */

    /* iterative */
    double *E;                  /* (L,3) copy of the unit vectors (DIM columns used) */
    double *f;                  /* (K,3) mass-wise vectors of the product C M^-1 C^T x */
    double *r, *p, *q, *x_best; /* (L) CG vectors (r, p alias c, t) */
    double diag_max;            /* largest diagonal entry of A */

    /* the last iterative solve, for diagnostics and tests */
    ln_int iterations;
    double residual;            /* least recursive residual |b - A x| / |b| reached */
    int stop;                   /* enum mn_stop */
};

static void mn_release_buffers(struct ln_minnorm_work *w)
{
    free(w->a); free(w->perm); free(w->diag); free(w->E); free(w->f);
    w->a = NULL; w->perm = NULL; w->diag = NULL; w->E = NULL; w->f = NULL;
    w->c = w->t = w->r = w->p = w->q = w->x_best = NULL;
    w->L = w->K = 0;
    w->dense_capacity = 0;
}

/* Make d->minnorm hold vectors for L links and K masses and, if dense, an L x L matrix. */
static int mn_reserve(ln_data *d, ln_int L, ln_int K, int dense)
{
    struct ln_minnorm_work *w = d->minnorm;
    if (!w) {
        w = calloc(1, sizeof *w);
        if (!w) return LN_NO_MEMORY;
        w->rank = -1;
        d->minnorm = w;
    }
    if (L > w->L || K > w->K || !w->perm) {
        ln_int nL = L > w->L ? L : w->L, nK = K > w->K ? K : w->K;
        mn_release_buffers(w);
        size_t sL = (size_t)(nL > 0 ? nL : 1), sK = (size_t)(nK > 0 ? nK : 1);
        w->perm = malloc(sL * sizeof(ln_int));
        w->diag = malloc(5 * sL * sizeof(double));     /* diag, c, t, q, x_best */
        w->E = malloc(3 * sL * sizeof(double));
        w->f = malloc(3 * sK * sizeof(double));
        if (!w->perm || !w->diag || !w->E || !w->f) {
            mn_release_buffers(w);
            return LN_NO_MEMORY;
        }
        w->c = w->diag + sL;
        w->t = w->diag + 2 * sL;
        w->q = w->diag + 3 * sL;
        w->x_best = w->diag + 4 * sL;
        w->r = w->c;
        w->p = w->t;
        w->L = nL;
        w->K = nK;
    }
    if (dense) {
        size_t n = (size_t)(L > 0 ? L : 1);
        if (n > SIZE_MAX / sizeof(double) / n) return LN_NO_MEMORY;
        if (n * n > w->dense_capacity) {
            free(w->a);
            w->dense_capacity = 0;
            w->a = malloc(n * n * sizeof(double));
            if (!w->a) return LN_NO_MEMORY;
            w->dense_capacity = n * n;
        }
    }
    return LN_OK;
}

/* dst[j] -= sum_q coef[q * cs] * src[q * ld + j], j < n, q < nq: the update of one row by nq others, four
   at a time so that dst is read and written once per four source rows. */
static void mn_rows_update(ln_int n, double *restrict dst, const double *restrict coef, ln_int cs,
                           const double *restrict src, ln_int ld, ln_int nq)
{
    ln_int q = 0;
    for (; q + 4 <= nq; q += 4) {
        const double c0 = coef[q * cs], c1 = coef[(q + 1) * cs], c2 = coef[(q + 2) * cs], c3 = coef[(q + 3) * cs];
        const double *s0 = src + q * ld, *s1 = s0 + ld, *s2 = s1 + ld, *s3 = s2 + ld;
        for (ln_int j = 0; j < n; j++) dst[j] -= c0 * s0[j] + c1 * s1[j] + c2 * s2[j] + c3 * s3[j];
    }
    for (; q < nq; q++) {
        const double c0 = coef[q * cs];
        const double *s0 = src + q * ld;
        for (ln_int j = 0; j < n; j++) dst[j] -= c0 * s0[j];
    }
}

/* Symmetric swap of rows and columns k < p of the active block (rows and columns >= k, upper triangle) of a
   matrix being factored, and of columns k and p of the finished rows 0..k-1 of R. */
static void mn_swap(ln_int n, double *a, ln_int lda, ln_int k, ln_int p)
{
    double tmp;
    for (ln_int i = 0; i < k; i++) {
        tmp = a[i * lda + k]; a[i * lda + k] = a[i * lda + p]; a[i * lda + p] = tmp;
    }
    tmp = a[k * lda + k]; a[k * lda + k] = a[p * lda + p]; a[p * lda + p] = tmp;
    for (ln_int j = k + 1; j < p; j++) {
        tmp = a[k * lda + j]; a[k * lda + j] = a[j * lda + p]; a[j * lda + p] = tmp;
    }
    for (ln_int j = p + 1; j < n; j++) {
        tmp = a[k * lda + j]; a[k * lda + j] = a[p * lda + j]; a[p * lda + j] = tmp;
    }
}

/* Cholesky factorisation R^T R of the symmetric n x n matrix in the upper triangle of a (row-major, leading
   dimension lda), R overwriting it row by row. With perm (n, on entry any numbering, permuted alongside),
   complete pivoting: each step takes the largest remaining diagonal entry of the Schur complement and the
   factorisation stops, returning the rank k, when it is not above tol. Without perm, no pivoting (an SPD
   matrix), stopping likewise at a diagonal entry not above tol. diag (n) is scratch.
   Blocked by panels of MN_PANEL rows (LAPACK's dpstrf): a panel's rows are computed from the rows of the
   panel before them, the trailing matrix is updated once per panel. The pivots are the exact Schur
   diagonals, so the choices are those of the unblocked algorithm. */
static ln_int mn_cholesky(ln_int n, double *a, ln_int lda, double *diag, ln_int *perm, double tol)
{
    for (ln_int j = 0; j < n; j++) diag[j] = a[j * lda + j];
    for (ln_int k0 = 0; k0 < n; k0 += MN_PANEL) {
        const ln_int kend = k0 + MN_PANEL < n ? k0 + MN_PANEL : n;
        for (ln_int k = k0; k < kend; k++) {
            ln_int piv = k;
            if (perm) {
                for (ln_int j = k + 1; j < n; j++)
                    if (diag[j] > diag[piv]) piv = j;
            }
            if (!(diag[piv] > tol)) return k;
            if (piv != k) {
                mn_swap(n, a, lda, k, piv);
                double td = diag[k]; diag[k] = diag[piv]; diag[piv] = td;
                ln_int tp = perm[k]; perm[k] = perm[piv]; perm[piv] = tp;
            }
            const double rkk = ln_sqrt(diag[k]);
            double *row = a + k * lda;
            /* the updates by this panel's earlier rows, not yet applied to the trailing matrix */
            mn_rows_update(n - k - 1, row + k + 1, a + k0 * lda + k, lda, a + k0 * lda + k + 1, lda, k - k0);
            row[k] = rkk;
            const double inv = 1.0 / rkk;
            for (ln_int j = k + 1; j < n; j++) {
                row[j] *= inv;
                diag[j] -= row[j] * row[j];
            }
        }
        /* trailing update by the whole panel: a[i][j] -= sum_q R[q][i] R[q][j], kend <= i <= j */
        for (ln_int i = kend; i < n; i++)
            mn_rows_update(n - i, a + i * lda + i, a + k0 * lda + i, lda, a + k0 * lda + i, lda, kend - k0);
    }
    return n;
}

/* y := R^-T y, R upper triangular n x n (leading dimension lda): forward substitution by rows of R. */
static void mn_solve_upper_transposed(ln_int n, const double *R, ln_int lda, double *y)
{
    for (ln_int i = 0; i < n; i++) {
        const double *row = R + i * lda;
        const double yi = y[i] / row[i];
        y[i] = yi;
        for (ln_int j = i + 1; j < n; j++) y[j] -= row[j] * yi;
    }
}

/* y := R^-1 y: back substitution. */
static void mn_solve_upper(ln_int n, const double *R, ln_int lda, double *y)
{
    for (ln_int i = n - 1; i >= 0; i--) {
        const double *row = R + i * lda;
        double s = y[i];
        for (ln_int j = i + 1; j < n; j++) s -= row[j] * y[j];
        y[i] = s / row[i];
    }
}

/* After a rank-r pivoted factorisation of the L x L matrix in w->a: W = R11^-1 R12 in place of R12, and the
   Cholesky factor S of Z^T Z = I + W^T W in a[r.., r..]. */
static void mn_null_space(struct ln_minnorm_work *w, ln_int L, ln_int r)
{
    double *a = w->a;
    const ln_int n0 = L - r;
    /* W: block back substitution from the last panel of rows up, each finished panel then applied once to
       all the rows above it */
    for (ln_int ib1 = r; ib1 > 0;) {
        const ln_int ib0 = ib1 - MN_PANEL > 0 ? ib1 - MN_PANEL : 0;
        for (ln_int i = ib1 - 1; i >= ib0; i--) {
            double *Wi = a + i * L + r;
            mn_rows_update(n0, Wi, a + i * L + i + 1, 1, a + (i + 1) * L + r, L, ib1 - 1 - i);
            const double inv = 1.0 / a[i * L + i];
            for (ln_int j = 0; j < n0; j++) Wi[j] *= inv;
        }
        for (ln_int i = 0; i < ib0; i++)
            mn_rows_update(n0, a + i * L + r, a + i * L + ib0, 1, a + ib0 * L + r, L, ib1 - ib0);
        ib1 = ib0;
    }
    /* G = I + W^T W (upper), accumulated as -W^T W by panels of rows of W, then negated */
    double *G = a + r * L + r;
    for (ln_int i = 0; i < n0; i++)
        for (ln_int j = i; j < n0; j++) G[i * L + j] = 0.0;
    for (ln_int i0 = 0; i0 < r; i0 += MN_PANEL) {
        const ln_int nq = r - i0 < MN_PANEL ? r - i0 : MN_PANEL;
        const double *Wp = a + i0 * L + r;
        for (ln_int i = 0; i < n0; i++) mn_rows_update(n0 - i, G + i * L + i, Wp + i, L, Wp + i, L, nq);
    }
    for (ln_int i = 0; i < n0; i++) {
        G[i * L + i] = 1.0 - G[i * L + i];
        for (ln_int j = i + 1; j < n0; j++) G[i * L + j] = -G[i * L + j];
    }
    mn_cholesky(n0, G, L, w->diag, NULL, 0.0);
}

/* y := y - Z (Z^T Z)^-1 Z^T y (pivoted numbering, length L): the component orthogonal to the null space.
   t (L - r) is scratch. */
static void mn_project_out_null(const struct ln_minnorm_work *w, ln_int L, double *y, double *t)
{
    const double *a = w->a;
    const ln_int r = w->rank, n0 = L - r;
    const double *S = a + r * L + r;
    for (ln_int j = 0; j < n0; j++) t[j] = y[r + j];        /* Z^T y = y_2 - W^T y_1 */
    for (ln_int i = 0; i < r; i++) {
        const double *Wi = a + i * L + r;
        const double yi = y[i];
        for (ln_int j = 0; j < n0; j++) t[j] -= Wi[j] * yi;
    }
    mn_solve_upper_transposed(n0, S, L, t);
    mn_solve_upper(n0, S, L, t);
    for (ln_int i = 0; i < r; i++) {                      /* y -= Z t = [-W t; t] */
        const double *Wi = a + i * L + r;
        double s = 0.0;
        for (ln_int j = 0; j < n0; j++) s += Wi[j] * t[j];
        y[i] += s;
    }
    for (ln_int j = 0; j < n0; j++) y[r + j] -= t[j];
}

/* Factor the assembled upper triangle of A in w->a (link numbering). */
static void mn_dense_factor(struct ln_minnorm_work *w, ln_int L, double rank_tol)
{
    double *a = w->a;
    double d0 = 0.0;
    for (ln_int i = 0; i < L; i++) {
        w->perm[i] = i;
        if (a[i * L + i] > d0) d0 = a[i * L + i];
    }
    w->diag_max = d0;
    const ln_int r = d0 > 0.0 ? mn_cholesky(L, a, L, w->diag, w->perm, rank_tol * d0) : 0;
    w->rank = r;
    if (r > 0 && r < L) mn_null_space(w, L, r);
}

static void mn_dense_solve(const struct ln_minnorm_work *w, ln_int L, const double *b, double *x)
{
    const ln_int r = w->rank;
    if (r == 0) {                                          /* A = 0: every b is inconsistent but 0 */
        for (ln_int i = 0; i < L; i++) x[i] = 0.0;
        return;
    }
    double *c = w->c, *t = w->t;
    for (ln_int i = 0; i < L; i++) c[i] = b[w->perm[i]];
    if (r < L) mn_project_out_null(w, L, c, t);            /* b's self-stress component carries no equation */
    mn_solve_upper_transposed(r, w->a, L, c);              /* basic solution: R11^T R11 x_1 = c_1, x_2 = 0 */
    mn_solve_upper(r, w->a, L, c);
    for (ln_int i = r; i < L; i++) c[i] = 0.0;
    if (r < L) mn_project_out_null(w, L, c, t);            /* minimum norm: drop the self-stresses (27) */
    for (ln_int i = 0; i < L; i++) x[w->perm[i]] = c[i];
}

static double mn_dot(ln_int n, const double *u, const double *v)
{
    double s = 0.0;
    for (ln_int i = 0; i < n; i++) s += u[i] * v[i];
    return s;
}

#endif /* LINKNET_MINNORM_COMMON */

#if DIM == 3
void ln_minnorm_free(struct ln_minnorm_work *w)
{
    if (!w) return;
    mn_release_buffers(w);
    free(w);
}

ln_int ln_minnorm_rank(const struct ln_minnorm_work *w)
{
    return (w && w->dense) ? w->rank : -1;
}
#endif

/* y = A x = C M^-1 C^T x without assembling A: the forces f_k = sum_l x_l E_l (delta(k,k1(l)) - delta(k,k2(l)))
   of (31), scaled by 1/M_k, then (A x)_l = E_l . (f_k1/M_k1 - f_k2/M_k2), the left-hand side of (15). */
static void FN(mn_product)(const ln_model *m, const double *E, double *f, const double *x, double *y)
{
    const ln_int L = m->L, K = m->K;
    const ln_int *k1 = m->k1, *k2 = m->k2;
    for (ln_int i = 0; i < K * DIM; i++) f[i] = 0.0;
    for (ln_int l = 0; l < L; l++) {
        const double xl = x[l];
        const double *e = E + l * DIM;
        double *fa = f + k1[l] * DIM, *fb = f + k2[l] * DIM;
        for (int i = 0; i < DIM; i++) {
            const double v = xl * e[i];
            fa[i] += v;
            fb[i] -= v;
        }
    }
    for (ln_int k = 0; k < K; k++) {
        const double s = m->inv_m[k];
        for (int i = 0; i < DIM; i++) f[k * DIM + i] *= s;
    }
    for (ln_int l = 0; l < L; l++) {
        const double *e = E + l * DIM, *fa = f + k1[l] * DIM, *fb = f + k2[l] * DIM;
        double s = 0.0;
        for (int i = 0; i < DIM; i++) s += e[i] * (fa[i] - fb[i]);
        y[l] = s;
    }
}

int FN(ln_minnorm_factor)(const ln_model *m, ln_data *d, const double *E)
{
    const ln_int L = m->L;
    const int dense = L <= m->dense_min_norm_limit;
    if (d->minnorm) d->minnorm->usable = 0;
    const int status = mn_reserve(d, L, m->K, dense);
    if (status != LN_OK) return status;
    struct ln_minnorm_work *w = d->minnorm;
    w->dense = dense;
    w->rank = dense ? 0 : -1;
    for (ln_int i = 0; i < L * DIM; i++)
        if (!isfinite(E[i])) return LN_OK;  /* not usable: the solves give NaN, for the caller's finiteness test */
    w->usable = 1;
    if (L == 0) return LN_OK;
    const double rank_tol = m->rank_tol > 0.0 ? m->rank_tol : MN_DEFAULT_RANK_TOL;

    if (dense) {
        /* A of (25) from the pairs: (18) on the diagonal, S(l,l') (E_l . E_l') / M(l,l') off it (21)-(22) */
        double *a = w->a;
        memset(a, 0, (size_t)L * (size_t)L * sizeof(double));
        for (ln_int p = 0; p < m->n_pairs; p++) {
            const ln_int i = m->pair_first[p], j = m->pair_second[p];
            const double *ei = E + i * DIM, *ej = E + j * DIM;
            double s = 0.0;
            for (int c = 0; c < DIM; c++) s += ei[c] * ej[c];
            const double v = m->pair_weight[p] * s;
            if (i <= j) a[i * L + j] += v;
            else a[j * L + i] += v;
        }
        mn_dense_factor(w, L, rank_tol);
        return LN_OK;
    }

    /* iterative: keep E for the products; the largest diagonal entry |E_l|^2 (1/M_k1 + 1/M_k2) scales the
       null-direction test */
    memcpy(w->E, E, (size_t)L * DIM * sizeof(double));
    double dmax = 0.0;
    for (ln_int l = 0; l < L; l++) {
        const double *e = E + l * DIM;
        double s = 0.0;
        for (int c = 0; c < DIM; c++) s += e[c] * e[c];
        s *= m->inv_m[m->k1[l]] + m->inv_m[m->k2[l]];
        if (s > dmax) dmax = s;
    }
    w->diag_max = dmax;
    return LN_OK;
}

void FN(ln_minnorm_solve)(const ln_model *m, ln_data *d, const double *b, double *x)
{
    struct ln_minnorm_work *w = d->minnorm;
    const ln_int L = m->L;
    if (!w || !w->usable) {
        for (ln_int i = 0; i < L; i++) x[i] = NAN;
        return;
    }
    if (w->dense) {
        mn_dense_solve(w, L, b, x);
        return;
    }

    const double rank_tol = m->rank_tol > 0.0 ? m->rank_tol : MN_DEFAULT_RANK_TOL;
    double *r = w->r, *p = w->p, *q = w->q, *xb = w->x_best;
    for (ln_int i = 0; i < L; i++) {
        x[i] = 0.0;
        r[i] = b[i];
        p[i] = b[i];
    }
    double rr = mn_dot(L, r, r);
    const double bnorm = ln_sqrt(rr);
    w->iterations = 0;
    w->residual = 0.0;
    w->stop = MN_STOP_CONVERGED;
    if (bnorm == 0.0) return;
    if (!isfinite(bnorm)) {
        for (ln_int i = 0; i < L; i++) x[i] = NAN;
        return;
    }
    const double null_cut = rank_tol * w->diag_max;
    const ln_int max_iter = 10 * L + 100;
    double best = bnorm;            /* least residual so far; x holds its iterate while current_is_best */
    ln_int it_best = 0, it = 0;
    int current_is_best = 1;
    w->stop = MN_STOP_MAX_ITER;
    while (it < max_iter) {
        it++;
        FN(mn_product)(m, w->E, w->f, p, q);
        double pq = 0.0, pp = 0.0;
        for (ln_int i = 0; i < L; i++) {
            pq += p[i] * q[i];
            pp += p[i] * p[i];
        }
        if (!(pq > null_cut * pp)) {
            w->stop = MN_STOP_NULL_DIRECTION;
            break;
        }
        const double alpha = rr / pq;
        double rr_new = 0.0;
        for (ln_int i = 0; i < L; i++) {
            r[i] -= alpha * q[i];
            rr_new += r[i] * r[i];
        }
        const double res = ln_sqrt(rr_new);
        if (res < best) {
            best = res;
            it_best = it;
            current_is_best = 1;
        } else if (current_is_best) {
            memcpy(xb, x, (size_t)L * sizeof(double));
            current_is_best = 0;
        }
        for (ln_int i = 0; i < L; i++) x[i] += alpha * p[i];
        if (res <= MN_CG_RTOL * bnorm) {
            w->stop = MN_STOP_CONVERGED;
            break;
        }
        if (it - it_best > (it_best > MN_CG_STALL_MIN ? it_best : MN_CG_STALL_MIN)) {
            w->stop = MN_STOP_STAGNATED;
            break;
        }
        const double beta = rr_new / rr;
        for (ln_int i = 0; i < L; i++) p[i] = r[i] + beta * p[i];
        rr = rr_new;
    }
    if (!current_is_best) memcpy(x, xb, (size_t)L * sizeof(double));
    w->iterations = it;
    w->residual = best / bnorm;
}
