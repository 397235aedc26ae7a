/* The right-hand side: dU/dt of (9) with the tensions of (25)-(26).
 *
 *   M_k dU_k/dt = F_k + sum_l T_l E_l (delta(k,k1(l)) - delta(k,k2(l)))             (9)
 *   A T = B,   B_l = |U_k2 - U_k1|^2 / R_l + E_l . (F_k2/M_k2 - F_k1/M_k1)           (25), (26)
 *
 * Anchored masses have 1/M = 0, so they neither move by the forces nor enter A. A driven anchor's row of F holds
 * its prescribed acceleration A_a (drive.c), which B takes with weight 1 and which is its dU/dt. On a chain the unit vectors, A's
 * entries, its pivots, B and the forward substitution are one sweep along the path, and the back
 * substitution, adding each link's force as soon as T_l is known, is the other: the elimination's
 * dependency chain sets the speed, and the rest of the work fits in its shadow.
 */
#include <math.h>

#include "../dim.h"
#include "../linknet.h"
#include "../stages.h"

/* E_l of (8) into E and B_l of (26) for link l; returns |E_l|^2 (for A's diagonal). */
static inline double link_terms(const ln_model *m, const double *X, const double *U, const double *F, ln_int l,
                                double *E, double *B_l)
{
    const ln_int a = m->k1[l], b = m->k2[l];
    const double r = m->inv_R[l], ia = m->accel_weight[a], ib = m->accel_weight[b];  /* 1/M; 1 on driven anchors */
    double sq = 0.0, du2 = 0.0, proj = 0.0;
    for (int e = 0; e < DIM; e++) {
        const double u = (X[b * DIM + e] - X[a * DIM + e]) * r;
        E[l * DIM + e] = u;
        sq += u * u;
        const double du = U[b * DIM + e] - U[a * DIM + e];
        du2 += du * du;
        proj += u * (F[b * DIM + e] * ib - F[a * DIM + e] * ia);
    }
    *B_l = du2 * r + proj;
    return sq;
}

static inline void scatter_link_force(const ln_model *m, const double *E, ln_int l, double T_l, double *acc)
{
    const ln_int a = m->k1[l], b = m->k2[l];
    for (int e = 0; e < DIM; e++) {
        const double f = T_l * E[l * DIM + e];
        acc[a * DIM + e] += f;
        acc[b * DIM + e] -= f;
    }
}

/* The chain's tensions in two sweeps (refactor 0: the factorisation at X is there already). Returns 0, or 1
   when a pivot vanished (the caller takes the general route with its minimum-norm solve). */
LN_ALWAYS_INLINE int chain_tensions(const ln_model *m, ln_data *d, const double *X, const double *U, const double *F,
                          double *E, double *T, double *acc, int refactor)
{
    const ln_int L = m->L;
    const ln_int *order = m->chain_order;
    double *w = d->work;
    const double *sub = d->chain_sub, *Dinv = d->chain_Dinv;
    int singular = 0;
    for (ln_int i = 0; i < L; i++) {
        const ln_int l = order[i];
        double rhs;
        const double sq = link_terms(m, X, U, F, l, E, &rhs);
        if (refactor && !chain_pivot(m, d, i, mode_diagonal(m, l, m->chain_diag_weight[i] * sq),
                                     i > 0 ? chain_off(m, E, i) : 0.0))
            singular = 1;
        if (i > 0) rhs -= sub[i] * w[i - 1];
        w[i] = rhs;
    }
    if (singular) return 1;
    double x = 0.0;
    for (ln_int i = L - 1; i >= 0; i--) {
        x = (i == L - 1) ? w[i] * Dinv[i] : w[i] * Dinv[i] - sub[i + 1] * x;
        const ln_int l = order[i];
        T[l] = x;
        scatter_link_force(m, E, l, x, acc);
    }
    return 0;
}

/* The tensions on the general route (trees, general graphs, minimum-norm solves, a chain at a vanishing pivot),
   their forces added into acc. */
LN_NOINLINE int general_tensions(const ln_model *m, ln_data *d, const double *X, const double *U, const double *F,
                                 double *E, double *T, double *acc, int refactor)
{
    FN(ln_unit_vectors)(m, X, E);
    if (refactor) {
        /* a chain whose sweep just met a vanishing pivot goes straight to the minimum-norm path */
        const int status = m->solver == LN_SOLVER_CHAIN ? FN(ln_factor_singular)(m, d, E)
                                                        : FN(ln_factor_tension_matrix)(m, d, E);
        if (status != LN_OK) return status;
    }
    double *B = d->B;
    for (ln_int l = 0; l < m->L; l++) link_terms(m, X, U, F, l, E, &B[l]);
    FN(ln_solve_tension_system)(m, d, B, T);
    for (ln_int l = 0; l < m->L; l++) scatter_link_force(m, E, l, T[l], acc);
    return LN_OK;
}

/* The right-hand side as the step loops call it (inlined there; ln_accelerations for everyone else). */
LN_ALWAYS_INLINE int accelerations(const ln_model *m, ln_data *d, const double *X, const double *U,
                                   const double *F_base, double *acc, double *T, int refactor)
{
    const ln_int K = m->K, L = m->L;
    double *E = d->E1;
    const double *F = F_base;
    if (m->n_elements > 0) {
        FN(ln_scene_forces)(m, X, U, F_base, d->F);
        F = d->F;
    }
    for (ln_int i = 0; i < K * DIM; i++) acc[i] = F[i];
    int general = L > 0 && m->solver != LN_SOLVER_CHAIN;
    if (L > 0 && m->solver == LN_SOLVER_CHAIN) {
        if (chain_tensions(m, d, X, U, F, E, T, acc, refactor || d->singular)) {
            general = 1;  /* a singular configuration: minimum-norm tensions below */
            refactor = 1;
            for (ln_int i = 0; i < K * DIM; i++) acc[i] = F[i];
        } else {
            d->singular = 0;
        }
    }
    if (general) {
        const int status = general_tensions(m, d, X, U, F, E, T, acc, refactor);
        if (status != LN_OK) return status;
    }
    double total = 0.0;
    for (ln_int k = 0; k < K; k++) {
        const double im = m->inv_m[k];
        for (int e = 0; e < DIM; e++) {
            acc[k * DIM + e] *= im;
            total += acc[k * DIM + e];
        }
    }
    for (ln_int a = 0; a < m->n_driven; a++)
        for (int e = 0; e < DIM; e++) acc[m->driven_idx[a] * DIM + e] = F[m->driven_idx[a] * DIM + e];
    return isfinite(total) ? LN_OK : LN_NON_FINITE;
}

int FN(ln_accelerations)(const ln_model *m, ln_data *d, const double *X, const double *U, const double *F_base,
                         double *acc, double *T, int refactor)
{
    return accelerations(m, d, X, U, F_base, acc, T, refactor);
}
