/* Projections onto the constraint manifolds: positions onto (11), velocities onto (12).
 *
 * Positions: Xc moves along M^-1 C(E_dir)^T mu until every |X_k2 - X_k1|^2 = R_l^2 (11). Simplified Newton:
 * the matrix A(E_dir) = C(E_dir) M^-1 C(E_dir)^T is factored already (RATTLE: at the start of its step;
 * Runge-Kutta: at the new point). The residual is phi_l = (|X_k2 - X_k1|^2 - R_l^2) / (2 R_l), a length.
 * Converged when every |phi_l| is within tol R_l, never below the round-off floor of computing
 * |X_k2 - X_k1| from coordinates of size |X|; simplified Newton is given up when it contracts too slowly.
 * Exact Newton then takes over, with a backtracking line search on the largest scaled residual. Its stopping
 * rule follows the conditioning: a Newton step cannot remove the part of phi it leaves by construction,
 * r = phi - J mu (the solve's own rounding, about eps kappa(J) |phi|, and on redundant links the component of
 * phi along the self-stresses, which no step along M^-1 C^T changes to first order), so the iteration also
 * stops, at its floor, once every |phi_l| is within its round-off floor plus 2 |r_l|. The floor reached
 * (relative) and how often a projection stopped there are counted in d->floor_reached, d->floor_stops.
 *
 * Velocities: the closest U satisfying (12) in the mass metric, U -= M^-1 C^T mu with A(X) mu = C U.
 */
#include <math.h>
#include <stdlib.h>

#include "../dim.h"
#include "../linknet.h"
#include "../ln_math.h"
#include "../stages.h"

LN_SCALAR_LOOPS_BEGIN

#define EPS 2.220446049250313e-16
#define KRYLOV_DIM 30        /* GMRES restart length of the exact-Newton solve */
#define KRYLOV_RESTARTS 10
#define KRYLOV_RTOL 1e-12
#define KRYLOV_PIVOT_CUT 1e-12  /* GMRES's triangular factor: pivots below this times the largest count as zero */
#define LINE_SEARCH_HALVINGS 8

static inline double length_residual(const ln_model *m, const double *Xc, ln_int l)
{
    const ln_int a = m->k1[l], b = m->k2[l];
    double sq = 0.0;
    for (int e = 0; e < DIM; e++) {
        const double dx = Xc[b * DIM + e] - Xc[a * DIM + e];
        sq += dx * dx;
    }
    return (sq - m->R[l] * m->R[l]) * (0.5 * m->inv_R[l]);
}

LN_ALWAYS_INLINE void residual_floor(const ln_model *m, const double *Xc, double tol, double *inv_scale)
{
    for (ln_int l = 0; l < m->L; l++) {
        const ln_int a = m->k1[l], b = m->k2[l];
        double size_a = 0.0, size_b = 0.0;
        for (int e = 0; e < DIM; e++) {
            size_a = ln_fmax(size_a, fabs(Xc[a * DIM + e]));
            size_b = ln_fmax(size_b, fabs(Xc[b * DIM + e]));
        }
        inv_scale[l] = 1.0 / (m->R[l] * tol + 8.0 * EPS * (size_a + size_b));
    }
}

/* phi_l of (11) for every link into phi; returns the largest |phi_l| in units of its convergence scale. */
static double residuals(const ln_model *m, const double *Xc, const double *inv_scale, double *phi)
{
    double worst = 0.0;
    for (ln_int l = 0; l < m->L; l++) {
        phi[l] = length_residual(m, Xc, l);
        const double r = fabs(phi[l]) * inv_scale[l];
        if (!(r <= worst)) worst = r;
    }
    return worst;
}

static void record_failure(const ln_model *m, ln_data *d, const double *Xc, ln_int iterations, double before)
{
    double worst = -1.0;
    for (ln_int l = 0; l < m->L; l++) {
        const double r = fabs(length_residual(m, Xc, l)) * m->inv_R[l];
        if (r > worst || !(r == r)) {
            worst = r;
            d->fail_link = l;
        }
    }
    d->fail_residual = worst;
    d->fail_before = before;
    d->fail_iterations = iterations;
}

/* The chain's back substitution with the multipliers applied as soon as each is known:
   V += scale M^-1 C(E)^T x, x = A^-1 w (w forward-substituted already). */
static inline void chain_back_substitution(const ln_model *m, const ln_data *d, const double *w, const double *E,
                                           double scale, double *V)
{
    const ln_int L = m->L;
    const ln_int *order = m->chain_order;
    const double *sub = d->chain_sub, *Dinv = d->chain_Dinv;
    double x = 0.0;
    for (ln_int i = L - 1; i >= 0; i--) {
        x = (i == L - 1) ? w[i] * Dinv[i] : w[i] * Dinv[i] - sub[i + 1] * x;
        const ln_int l = order[i], a = m->k1[l], b = m->k2[l];
        const double fa = scale * x * m->inv_m[a], fb = scale * x * m->inv_m[b];
        for (int e = 0; e < DIM; e++) {
            V[a * DIM + e] += fa * E[l * DIM + e];
            V[b * DIM + e] -= fb * E[l * DIM + e];
        }
    }
}

/* The chain's Newton iteration: the residuals of (11), the convergence test and the forward substitution in
   one sweep; the back substitution, each multiplier applied as soon as it is known, in the other. */
LN_ALWAYS_INLINE int project_positions_chain(const ln_model *m, ln_data *d, double *Xc, const double *E_dir, double tol,
                                   ln_int max_iter, double *first)
{
    const ln_int L = m->L;
    const ln_int *order = m->chain_order;
    double *w = d->work, *inv_scale = d->scale;
    const double *sub = d->chain_sub;
    residual_floor(m, Xc, tol, inv_scale);
    double previous = 1e300;
    for (ln_int it = 0; it < max_iter; it++) {
        double worst = 0.0;
        for (ln_int i = 0; i < L; i++) {
            const ln_int l = order[i];
            double phi = length_residual(m, Xc, l);
            const double r = fabs(phi) * inv_scale[l];
            if (!(r <= worst)) worst = r;
            if (i > 0) phi -= sub[i] * w[i - 1];
            w[i] = phi;
        }
        if (*first < 0) *first = worst * tol;
        if (worst <= 1.0) return LN_OK;
        if (!(worst < 1e300) || (it > 2 && worst > 0.3 * previous)) break;
        previous = worst;
        chain_back_substitution(m, d, w, E_dir, 1.0, Xc);
    }
    return LN_PROJECTION_FAILED;
}

/* Simplified Newton with A(E_dir) factored (the chain's own sweeps, or the general solve). Returns LN_OK,
   or LN_PROJECTION_FAILED when it contracts too slowly (it is then handed to exact Newton), with Xc at its best
   iterate. */
LN_ALWAYS_INLINE int simplified_newton(const ln_model *m, ln_data *d, double *Xc, const double *E_dir, double tol,
                             ln_int max_iter, double *first)
{
    if (m->solver == LN_SOLVER_CHAIN && !d->singular)
        return project_positions_chain(m, d, Xc, E_dir, tol, max_iter, first);
    double *phi = d->phi, *mu = d->mu, *inv_scale = d->scale;
    residual_floor(m, Xc, tol, inv_scale);
    double previous = 1e300;
    for (ln_int it = 0; it < max_iter; it++) {
        const double worst = residuals(m, Xc, inv_scale, phi);
        if (*first < 0) *first = worst * tol;
        if (worst <= 1.0) return LN_OK;
        if (!(worst < 1e300) || (it > 2 && worst > 0.3 * previous)) {
            /* a step that made things worse is undone: Gauss-Newton goes on from here, and from a point far
               off (11) a redundant system's least squares can settle off the manifold for good */
            if (it > 0 && !(worst <= previous)) FN(ln_add_correction)(m, E_dir, mu, -1.0, Xc);
            break;
        }
        previous = worst;
        FN(ln_solve_tension_system)(m, d, phi, mu);
        FN(ln_add_correction)(m, E_dir, mu, 1.0, Xc);
    }
    return LN_PROJECTION_FAILED;
}

/* y = J x with J = C(Xc) M^-1 C(E_dir)^T, the exact Newton matrix of the position stage: moving along
   M^-1 C(E_dir)^T x changes phi_l by -(J x)_l. dX: (K,DIM) scratch. */
static void newton_matrix_product(const ln_model *m, const double *Xc, const double *E_dir, const double *x,
                                  double *dX, double *y)
{
    for (ln_int i = 0; i < m->K * DIM; i++) dX[i] = 0.0;
    FN(ln_add_correction)(m, E_dir, x, 1.0, dX);
    for (ln_int l = 0; l < m->L; l++) {
        const ln_int a = m->k1[l], b = m->k2[l];
        double s = 0.0;
        for (int e = 0; e < DIM; e++)
            s += (Xc[b * DIM + e] - Xc[a * DIM + e]) * m->inv_R[l] * (dX[a * DIM + e] - dX[b * DIM + e]);
        y[l] = s;
    }
}

static inline ln_int krylov_need(ln_int L)
{
    const ln_int n = KRYLOV_DIM;
    return (n + 1) * L + (n + 1) * n + 4 * (n + 1) + 2 * L;
}

/* d->krylov holds at least need doubles (grown, never shrunk); 0 when out of memory. */
static int reserve_krylov(ln_data *d, ln_int need)
{
    if (d->krylov_size >= need) return 1;
    free(d->krylov);
    d->krylov = malloc((size_t)need * sizeof(double));
    d->krylov_size = d->krylov ? need : 0;
    return d->krylov != NULL;
}

/* mu = J^-1 phi by GMRES, right-preconditioned with the factored A(E_dir) (close to J: few iterations). */
static int newton_solve(const ln_model *m, ln_data *d, const double *Xc, const double *E_dir, const double *phi,
                        double *mu)
{
    const ln_int L = m->L, n = KRYLOV_DIM;
    if (!reserve_krylov(d, krylov_need(L) + L)) return LN_NO_MEMORY;  /* the last L: exact_newton's r */
    double *V = d->krylov, *H = V + (n + 1) * L, *cs = H + (n + 1) * n, *sn = cs + (n + 1), *g = sn + (n + 1);
    double *y = g + (n + 1), *z = y + (n + 1), *w = z + L, *dX = d->acc1;
    double beta0 = 0.0;
    for (ln_int l = 0; l < L; l++) {
        mu[l] = 0.0;
        beta0 += phi[l] * phi[l];
    }
    beta0 = ln_sqrt(beta0);
    if (beta0 == 0.0) return LN_OK;
    for (int restart = 0; restart < KRYLOV_RESTARTS; restart++) {
        /* r = phi - J mu */
        newton_matrix_product(m, Xc, E_dir, mu, dX, w);
        double beta = 0.0;
        for (ln_int l = 0; l < L; l++) {
            V[l] = phi[l] - w[l];
            beta += V[l] * V[l];
        }
        beta = ln_sqrt(beta);
        if (beta <= KRYLOV_RTOL * beta0) return LN_OK;
        for (ln_int l = 0; l < L; l++) V[l] /= beta;
        for (ln_int i = 0; i <= n; i++) g[i] = 0.0;
        g[0] = beta;
        ln_int j = 0;
        for (; j < n; j++) {
            FN(ln_solve_tension_system)(m, d, V + j * L, z);
            newton_matrix_product(m, Xc, E_dir, z, dX, w);
            for (ln_int i = 0; i <= j; i++) {  /* modified Gram-Schmidt */
                double h = 0.0;
                for (ln_int l = 0; l < L; l++) h += w[l] * V[i * L + l];
                H[i * n + j] = h;
                for (ln_int l = 0; l < L; l++) w[l] -= h * V[i * L + l];
            }
            double h = 0.0;
            for (ln_int l = 0; l < L; l++) h += w[l] * w[l];
            h = ln_sqrt(h);
            H[(j + 1) * n + j] = h;
            if (h > 0.0)
                for (ln_int l = 0; l < L; l++) V[(j + 1) * L + l] = w[l] / h;
            for (ln_int i = 0; i < j; i++) {  /* the earlier Givens rotations */
                const double a = H[i * n + j], b = H[(i + 1) * n + j];
                H[i * n + j] = cs[i] * a + sn[i] * b;
                H[(i + 1) * n + j] = -sn[i] * a + cs[i] * b;
            }
            const double a = H[j * n + j], b = H[(j + 1) * n + j], r = ln_hypot(a, b);
            cs[j] = r > 0.0 ? a / r : 1.0;
            sn[j] = r > 0.0 ? b / r : 0.0;
            H[j * n + j] = r;
            H[(j + 1) * n + j] = 0.0;
            g[j + 1] = -sn[j] * g[j];
            g[j] = cs[j] * g[j];
            if (fabs(g[j + 1]) <= KRYLOV_RTOL * beta0 || h == 0.0) {
                j++;
                break;
            }
        }
        /* y = H^-1 g (upper triangular), mu += P^-1 V y. On a singular J (redundant links: phi's component
           along the self-stresses is out of its range) the Krylov space meets J's null space and a pivot of H
           falls to round-off: that direction is dropped, the least-squares step of the rest kept. */
        double pivot_max = 0.0;
        for (ln_int i = 0; i < j; i++) pivot_max = ln_fmax(pivot_max, fabs(H[i * n + i]));
        for (ln_int i = j - 1; i >= 0; i--) {
            double s = g[i];
            for (ln_int k = i + 1; k < j; k++) s -= H[i * n + k] * y[k];
            y[i] = fabs(H[i * n + i]) > KRYLOV_PIVOT_CUT * pivot_max ? s / H[i * n + i] : 0.0;
        }
        for (ln_int l = 0; l < L; l++) w[l] = 0.0;
        for (ln_int i = 0; i < j; i++)
            for (ln_int l = 0; l < L; l++) w[l] += y[i] * V[i * L + l];
        FN(ln_solve_tension_system)(m, d, w, z);
        for (ln_int l = 0; l < L; l++) mu[l] += z[l];
    }
    return LN_OK;  /* an inexact Newton step still contracts; the outer iteration judges convergence */
}

/* Every |phi_l| within its round-off floor plus m->floor_safety |r_l|, r = phi - J mu of the step just taken: the
   step left no more than it had to. Returns the largest |phi_l| / R_l then, or -1. */
static double at_floor(const ln_model *m, const double *phi, const double *inv_scale, const double *r)
{
    double reached = 0.0;
    for (ln_int l = 0; l < m->L; l++) {
        if (fabs(phi[l]) > 1.0 / inv_scale[l] + m->floor_safety * fabs(r[l])) return -1.0;
        reached = ln_fmax(reached, fabs(phi[l]) * m->inv_R[l]);
    }
    return reached;
}

/* One step of exact Newton or Gauss-Newton, given the multipliers mu along M^-1 C(E)^T and r = J mu on entry: r
   becomes phi - J mu (what the step leaves by construction) and the floor it allows is recorded; Xc moves by the
   step, halved while it does not lower the largest scaled residual *worst (d->phi and *worst then describe the new
   point). Returns 1 when the projection stops there at its floor (counted), 0 to go on. */
static int newton_step(const ln_model *m, ln_data *d, double *Xc, const double *E, const double *mu, double *r,
                       double *worst)
{
    double *phi = d->phi;
    const double *inv_scale = d->scale;
    double floor = 0.0;
    for (ln_int l = 0; l < m->L; l++) {
        r[l] = phi[l] - r[l];
        floor = ln_fmax(floor, (1.0 / inv_scale[l] + m->floor_safety * fabs(r[l])) * m->inv_R[l]);
    }
    d->fail_floor = floor;
    double step = 1.0;
    FN(ln_add_correction)(m, E, mu, step, Xc);
    double trial = residuals(m, Xc, inv_scale, phi);
    for (int halving = 0; halving < LINE_SEARCH_HALVINGS && !(trial < *worst) && trial > 1.0; halving++) {
        FN(ln_add_correction)(m, E, mu, -0.5 * step, Xc);
        step *= 0.5;
        trial = residuals(m, Xc, inv_scale, phi);
    }
    *worst = trial;
    if (trial > 1.0 && trial <= m->floor_cap) {
        const double reached = at_floor(m, phi, inv_scale, r);
        if (reached >= 0.0) {
            d->floor_stops++;
            d->floor_reached = ln_fmax(d->floor_reached, reached);
            return 1;
        }
    }
    return 0;
}

/* Exact Newton from the starting point X_start, for steps where the directions turn too much within a step
   for simplified Newton (a whipping chain's tip) or where simplified Newton stalls on a badly conditioned or
   redundant system: J = C(Xc) M^-1 C(E_dir)^T, the point reached is the same (it lies on (11) along
   M^-1 C(E_dir)^T from the start). A step that does not lower the largest scaled residual is halved. */
static int exact_newton(const ln_model *m, ln_data *d, double *Xc, const double *X_start, const double *E_dir,
                        double tol, ln_int max_iter)
{
    double *phi = d->phi, *mu = d->mu, *inv_scale = d->scale;
    for (ln_int i = 0; i < m->K * DIM; i++) Xc[i] = X_start[i];
    residual_floor(m, Xc, tol, inv_scale);
    double worst = residuals(m, Xc, inv_scale, phi);
    d->fail_floor = 0.0;
    for (ln_int it = 0; it < max_iter; it++) {
        if (worst <= 1.0) return LN_OK;
        if (!(worst < 1e300)) break;
        const int status = newton_solve(m, d, Xc, E_dir, phi, mu);
        if (status != LN_OK) return status;
        double *r = d->krylov + krylov_need(m->L);  /* r = phi - J mu: what this step leaves by construction */
        newton_matrix_product(m, Xc, E_dir, mu, d->acc1, r);
        if (newton_step(m, d, Xc, E_dir, mu, r, &worst)) return LN_OK;
    }
    return LN_PROJECTION_FAILED;
}

/* Gauss-Newton from where simplified Newton stopped, for a singular A (redundant links, singular passages):
   every iteration moves along M^-1 C(Xc)^T mu with the minimum-norm mu = A(Xc)^+ phi, the closest point in the
   mass metric. The exact Newton matrix C(Xc) M^-1 C(E_dir)^T is singular there too, and in a way Krylov solves
   handle badly; simplified Newton has already brought the residual close, so the direction changes only the
   last small corrections. A step that does not lower the largest scaled residual is halved; the iteration
   stops at its floor as exact_newton does, with r = phi - A(Xc) mu (phi's component along the self-stresses at
   Xc, of second order in the distance to (11), and the minimum-norm solve's own rounding). */
static int gauss_newton(const ln_model *m, ln_data *d, double *Xc, double tol, ln_int max_iter)
{
    const ln_int L = m->L;
    double *phi = d->phi, *mu = d->mu, *inv_scale = d->scale;
    if (!reserve_krylov(d, L * (DIM + 1))) return LN_NO_MEMORY;
    double *E = d->krylov, *r = d->krylov + L * DIM;
    residual_floor(m, Xc, tol, inv_scale);
    double worst = residuals(m, Xc, inv_scale, phi);
    d->fail_floor = 0.0;
    for (ln_int it = 0; it < max_iter; it++) {
        if (worst <= 1.0) return LN_OK;
        if (!(worst < 1e300)) break;
        FN(ln_unit_vectors)(m, Xc, E);
        int status = FN(ln_factor_tension_matrix)(m, d, E);
        if (status != LN_OK) return status;
        FN(ln_solve_tension_system)(m, d, phi, mu);
        newton_matrix_product(m, Xc, E, mu, d->acc1, r);
        if (newton_step(m, d, Xc, E, mu, r, &worst)) return LN_OK;
    }
    return LN_PROJECTION_FAILED;
}

/* A Gauss-Newton that failed, once more from where it stopped, on the model with the finer minimum-norm cut
   retry_rank_tol: a near-self-stress (a flat braced cell pushed out of its plane: eigenvalue ~(delta/R)^2, a few
   1e-12 of the largest, below rank_tol) is then a direction to move along, not a self-stress (31) to leave out.
   The factorisation it leaves in d is, as the first Gauss-Newton's, of a point inside the iteration, which no caller
   solves with again. */
static int gauss_newton_retry(const ln_model *m, ln_data *d, double *Xc, double tol, ln_int max_iter)
{
    if (!(m->retry_rank_tol > 0.0)) return LN_PROJECTION_FAILED;
    ln_model finer = *m;
    finer.rank_tol = m->retry_rank_tol;
    return gauss_newton(&finer, d, Xc, tol, max_iter);
}

/* Where simplified Newton gave up: exact Newton from X_start, or Gauss-Newton where A is singular (retried with
   the finer cut only where it would fail, so every projection that converges without it is unchanged). */
LN_NOINLINE int project_positions_newton(const ln_model *m, ln_data *d, double *Xc, const double *X_start,
                                     const double *E_dir, double tol, ln_int max_iter, double before)
{
    d->exact_newton_projections++;
    int status;
    if (m->solver == LN_SOLVER_MIN_NORM || d->singular) {
        status = gauss_newton(m, d, Xc, tol, max_iter);
        if (status == LN_PROJECTION_FAILED) status = gauss_newton_retry(m, d, Xc, tol, max_iter);
    } else {
        status = exact_newton(m, d, Xc, X_start, E_dir, tol, max_iter);
    }
    if (status == LN_PROJECTION_FAILED) record_failure(m, d, Xc, max_iter, before);
    return status;
}

/* The position stage as the step loops call it (inlined there; ln_project_positions for everyone else). */
LN_ALWAYS_INLINE int project_positions(const ln_model *m, ln_data *d, double *Xc, const double *E_dir, double tol,
                                       ln_int max_iter)
{
    if (m->L == 0) return LN_OK;
    double *X_start = d->Xs == Xc ? d->Us : d->Xs;  /* a copy of the starting point, for exact Newton */
    for (ln_int i = 0; i < m->K * DIM; i++) X_start[i] = Xc[i];
    double before = -1.0;
    if (simplified_newton(m, d, Xc, E_dir, tol, max_iter, &before) == LN_OK) return LN_OK;
    return project_positions_newton(m, d, Xc, X_start, E_dir, tol, max_iter, before);
}

int FN(ln_project_positions)(const ln_model *m, ln_data *d, double *Xc, const double *E_dir, double tol,
                             ln_int max_iter)
{
    return project_positions(m, d, Xc, E_dir, tol, max_iter);
}

/* The chain's velocity projection in two sweeps: unit vectors, A's entries and pivots, C U and the forward
   substitution in one; the back substitution with the correction of U in the other. Returns 1 at a
   vanishing pivot (the caller takes the general route). */
LN_ALWAYS_INLINE int project_velocities_chain(const ln_model *m, ln_data *d, const double *X, double *U, double *E)
{
    const ln_int L = m->L;
    const ln_int *order = m->chain_order;
    double *w = d->work;
    int singular = 0;
    for (ln_int i = 0; i < L; i++) {
        const ln_int l = order[i], a = m->k1[l], b = m->k2[l];
        const double r = m->inv_R[l];
        double sq = 0.0, rhs = 0.0;
        for (int e = 0; e < DIM; e++) {
            const double u = (X[b * DIM + e] - X[a * DIM + e]) * r;
            E[l * DIM + e] = u;
            sq += u * u;
            rhs += u * (U[a * DIM + e] - U[b * DIM + e]);
        }
        if (!chain_pivot(m, d, i, mode_diagonal(m, l, m->chain_diag_weight[i] * sq), i > 0 ? chain_off(m, E, i) : 0.0))
            singular = 1;
        if (i > 0) rhs -= d->chain_sub[i] * w[i - 1];
        w[i] = rhs;
    }
    if (singular) return 1;
    chain_back_substitution(m, d, w, E, -1.0, U);
    d->singular = 0;
    return 0;
}

/* The velocity projection on the general route: trees, general graphs, minimum-norm solves, and a chain whose
   sweep met a vanishing pivot. */
LN_NOINLINE int project_velocities_general(const ln_model *m, ln_data *d, const double *X, double *U, double *E)
{
    const ln_int L = m->L;
    FN(ln_unit_vectors)(m, X, E);
    /* a chain whose sweep just met a vanishing pivot goes straight to the minimum-norm path */
    const int status = m->solver == LN_SOLVER_CHAIN ? FN(ln_factor_singular)(m, d, E)
                                                    : FN(ln_factor_tension_matrix)(m, d, E);
    if (status != LN_OK) return status;
    double *rhs = d->phi, *mu = d->mu;
    for (ln_int l = 0; l < L; l++) {
        const ln_int a = m->k1[l], b = m->k2[l];
        double s = 0.0;
        for (int e = 0; e < DIM; e++) s += E[l * DIM + e] * (U[a * DIM + e] - U[b * DIM + e]);
        rhs[l] = s;
    }
    FN(ln_solve_tension_system)(m, d, rhs, mu);
    FN(ln_add_correction)(m, E, mu, -1.0, U);
    return LN_OK;
}

/* The velocity stage as the step loops call it (inlined there; ln_project_velocities for everyone else). */
LN_ALWAYS_INLINE int project_velocities(const ln_model *m, ln_data *d, const double *X, double *U, double *E)
{
    if (m->L == 0) return LN_OK;
    if (m->solver == LN_SOLVER_CHAIN && !project_velocities_chain(m, d, X, U, E)) return LN_OK;
    return project_velocities_general(m, d, X, U, E);
}

int FN(ln_project_velocities)(const ln_model *m, ln_data *d, const double *X, double *U, double *E)
{
    return project_velocities(m, d, X, U, E);
}

#if DIM == 3
int ln_project_state(const ln_model *m, ln_data *d, double *X, double *U, int positions, double tol, ln_int max_iter,
                     double *mu)
{
    if (m->L == 0) return LN_OK;
    double *E = d->E0;
    int status;
    if (positions) {  /* along M^-1 C(X)^T mu from X itself: the closest point of (11) in the mass metric */
        FN(ln_unit_vectors)(m, X, E);
        if ((status = FN(ln_factor_tension_matrix)(m, d, E)) != LN_OK) return status;
        if ((status = project_positions(m, d, X, E, tol, max_iter)) != LN_OK) return status;
    }
    if (!mu) return project_velocities(m, d, X, U, E);
    /* the multipliers kept: A(X) mu = C U solved on the general factorisation (a chain's sweeps apply each
       multiplier as soon as it is known and keep none) */
    FN(ln_unit_vectors)(m, X, E);
    if ((status = FN(ln_factor_tension_matrix)(m, d, E)) != LN_OK) return status;
    double *rhs = d->phi;
    for (ln_int l = 0; l < m->L; l++) {
        const ln_int a = m->k1[l], b = m->k2[l];
        double sum = 0.0;
        for (int e = 0; e < 3; e++) sum += E[3 * l + e] * (U[3 * a + e] - U[3 * b + e]);
        rhs[l] = sum;
    }
    FN(ln_solve_tension_system)(m, d, rhs, mu);
    FN(ln_add_correction)(m, E, mu, -1.0, U);
    return LN_OK;
}
#endif

LN_SCALAR_LOOPS_END
