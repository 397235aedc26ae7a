/* The tension system (25)-(26): A = C M^-1 C^T from the unit vectors E_l of (8), factored on the path
   chosen once per scene, and its solutions.
 *
 * Off the manifold (11) A keeps the Jacobian form: diagonal |E_l|^2 (1/M_k1 + 1/M_k2) rather than the seed's
 * 1/M_k1 + 1/M_k2 of (18), off-diagonal S(l,l') (E_l . E_l') / M(l,l') of (21)-(22). That is what makes the
 * accelerations satisfy the twice-differentiated constraint (13) exactly at every state an integrator
 * visits; on the manifold the two agree.
 *
 * Chains are tridiagonal in path order: Thomas' elimination, two sweeps per right-hand side. Trees and
 * general graphs use the sparse LDL^T of ldl.h. Where a pivot vanishes (a singular configuration: a loop
 * passing a flat position, a taut string) or the scene has self-stresses, A is singular and the solves are
 * minimum-norm (stages/minnorm.c): any solution gives the same forces (31), the reported one has no
 * component along the self-stresses (27).
 */
#include <math.h>

#include "../dim.h"
#include "../ldl.h"
#include "../linknet.h"
#include "../stages.h"

/* A slack rope (stages/ropes.c) is out of the system: the mode's model has 1/R_l = 0 there, so its unit vector, its
   term of (26) and its residual of (11) vanish, and its zero diagonal entry of A takes 1 (T_l = 0, and the
   factorisation stays regular). A rod's 1/R_l is never 0: scenes without ropes take the same path as ever. */
static inline double mode_diagonal(const ln_model *m, ln_int l, double diag)
{
    return m->inv_R[l] != 0.0 ? diag : 1.0;
}

static inline double dot_rows(const double *E, ln_int p, ln_int q)
{
    double s = 0.0;
    for (int e = 0; e < DIM; e++) s += E[p * DIM + e] * E[q * DIM + e];
    return s;
}

void FN(ln_unit_vectors)(const ln_model *m, const double *X, double *E)
{
    for (ln_int l = 0; l < m->L; l++) {
        const ln_int a = m->k1[l], b = m->k2[l];
        const double r = m->inv_R[l];  /* a multiplication is several times cheaper than a division */
        for (int e = 0; e < DIM; e++) E[l * DIM + e] = (X[b * DIM + e] - X[a * DIM + e]) * r;
    }
}

/* One pivot of Thomas' elimination of the chain's tridiagonal A: position i of the path, diagonal entry
   diag, off-diagonal entry off to the previous position (0 at a path's start). Stores the multiplier and
   1/pivot; returns whether the pivot is usable (above pivot_tol times the diagonal). */
static inline int chain_pivot(const ln_model *m, ln_data *d, ln_int i, double diag, double off)
{
    double pivot = diag;
    if (off != 0.0) {
        const double mult = off * d->chain_Dinv[i - 1];
        d->chain_sub[i] = mult;
        pivot -= mult * off;
    } else {
        d->chain_sub[i] = 0.0;
    }
    if (pivot > m->pivot_tol * fabs(diag)) {
        d->chain_Dinv[i] = 1.0 / pivot;
        return 1;
    }
    d->chain_Dinv[i] = 0.0;
    return 0;
}

static inline double chain_off(const ln_model *m, const double *E, ln_int i)
{
    const double w = m->chain_off_weight[i];
    return w != 0.0 ? w * dot_rows(E, m->chain_order[i - 1], m->chain_order[i]) : 0.0;
}

/* Returns -1 or the first path position whose pivot vanished. */
static ln_int factor_chain(const ln_model *m, ln_data *d, const double *E)
{
    ln_int bad = -1;
    for (ln_int i = 0; i < m->L; i++) {
        const ln_int l = m->chain_order[i];
        const double diag = mode_diagonal(m, l, m->chain_diag_weight[i] * dot_rows(E, l, l));
        if (!chain_pivot(m, d, i, diag, i > 0 ? chain_off(m, E, i) : 0.0) && bad == -1) bad = i;
    }
    return bad;
}

static void solve_chain(const ln_model *m, ln_data *d, const double *b, double *out)
{
    const ln_int n = m->L;
    const ln_int *order = m->chain_order;
    double *w = d->work;
    if (n == 0) return;
    w[0] = b[order[0]];
    for (ln_int i = 1; i < n; i++) w[i] = b[order[i]] - d->chain_sub[i] * w[i - 1];
    w[n - 1] *= d->chain_Dinv[n - 1];
    out[order[n - 1]] = w[n - 1];
    for (ln_int i = n - 2; i >= 0; i--) {
        w[i] = w[i] * d->chain_Dinv[i] - d->chain_sub[i + 1] * w[i + 1];
        out[order[i]] = w[i];
    }
}

int FN(ln_factor_singular)(const ln_model *m, ln_data *d, const double *E)
{
    d->singular = 1;
    d->singular_events++;
    return FN(ln_minnorm_factor)(m, d, E);
}

int FN(ln_factor_tension_matrix)(const ln_model *m, ln_data *d, const double *E)
{
    d->singular = 0;
    switch (m->solver) {
    case LN_SOLVER_CHAIN:
        return factor_chain(m, d, E) < 0 ? LN_OK : FN(ln_factor_singular)(m, d, E);
    case LN_SOLVER_LDL:
        for (ln_int p = 0; p < m->n_pairs; p++)
            d->pair_values[p] = m->pair_weight[p] * dot_rows(E, m->pair_first[p], m->pair_second[p]);
        if (m->n_ropes)
            for (ln_int p = 0; p < m->n_pairs; p++)
                if (m->pair_first[p] == m->pair_second[p])
                    d->pair_values[p] = mode_diagonal(m, m->pair_first[p], d->pair_values[p]);
        return ln_ldl_factor(m->ldl, d->ldl, d->pair_values, m->pivot_tol) < 0 ? LN_OK : FN(ln_factor_singular)(m, d, E);
    case LN_SOLVER_MIN_NORM:
        d->singular = 1;  /* self-stresses: every solve is minimum-norm */
        return FN(ln_minnorm_factor)(m, d, E);
    default:
        return LN_OK;
    }
}

void FN(ln_solve_tension_system)(const ln_model *m, ln_data *d, const double *b, double *x)
{
    if (m->L == 0) return;
    if (d->singular) FN(ln_minnorm_solve)(m, d, b, x);
    else if (m->solver == LN_SOLVER_CHAIN) solve_chain(m, d, b, x);
    else ln_ldl_solve(m->ldl, d->ldl, b, x);
}

void FN(ln_add_correction)(const ln_model *m, const double *E, const double *mu, double scale, double *V)
{
    /* V += scale M^-1 C^T mu: +mu_l E_l on k1(l), -mu_l E_l on k2(l), as the link forces of (9) */
    for (ln_int l = 0; l < m->L; l++) {
        const ln_int a = m->k1[l], b = m->k2[l];
        const double f = scale * mu[l];
        const double fa = f * m->inv_m[a], fb = f * m->inv_m[b];
        for (int e = 0; e < DIM; e++) {
            V[a * DIM + e] += fa * E[l * DIM + e];
            V[b * DIM + e] -= fb * E[l * DIM + e];
        }
    }
}
