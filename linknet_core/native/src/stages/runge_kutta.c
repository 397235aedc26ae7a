/* Explicit embedded Runge-Kutta on the index-1 formulation, projected onto the constraint manifolds.
 *
 * The index-1 ODE is dX/dt = U (10), dU/dt = accelerations (9) with the tensions of (25)-(26). It keeps (13)
 * exactly but lets (11) and (12) drift, so after every accepted step the positions are projected onto (11)
 * and the velocities onto (12) (projections.c). The method is its tableau (method->AB, E1, E2): adding one
 * needs no code here. The step size follows the embedded error estimate (RMS norm of the embedded
 * difference, or DOP853's combined 5th/3rd-order estimate) with the controller of Hairer, Norsett and
 * Wanner, and the first step is their starting-step heuristic.
 */
#include <math.h>

#include "../dim.h"
#include "../drive.h"
#include "../linknet.h"
#include "../ln_math.h"
#include "../stages.h"
#include "../tension_peaks.h"

/* Up to this many coordinates a stage's point is summed coordinate by coordinate, above it block by block (measured:
   DOP853 per step on a planar pendulum (4 coordinates) 0.87 -> 0.53 us by coordinate, on chain_10 (22) 3.5 us by
   block against 4.05 us by coordinate). */
#define COMBINE_BY_COORDINATE 12

/* A stage's point: Xo = X0 + h sum_{j<n} coef[j] KX[j], Uo likewise from KU (zero coefficients skipped; KX, KU
   rows are (K,DIM) blocks), each coordinate's sum in j order from 0.0 either way. On a small scene the work is a
   few terms per coordinate, and the set-up of a (vectorized) loop over each block costs more than its sums; on
   a large one the loops over whole blocks are the fast order. */
static inline void combine(ln_int size, const double *X0, const double *U0, double h, const double *coef, ln_int n,
                           const double *KX, const double *KU, double *Xo, double *Uo)
{
    if (size <= COMBINE_BY_COORDINATE) {
        for (ln_int i = 0; i < size; i++) {
            double sx = 0.0, su = 0.0;
            for (ln_int j = 0; j < n; j++) {
                const double c = coef[j];
                if (c == 0.0) continue;
                sx += c * KX[j * size + i];
                su += c * KU[j * size + i];
            }
            Xo[i] = X0[i] + h * sx;
            Uo[i] = U0[i] + h * su;
        }
        return;
    }
    for (int part = 0; part < 2; part++) {
        const double *Y0 = part == 0 ? X0 : U0, *KY = part == 0 ? KX : KU;
        double *out = part == 0 ? Xo : Uo;
        for (ln_int i = 0; i < size; i++) out[i] = 0.0;
        for (ln_int j = 0; j < n; j++) {
            const double c = coef[j];
            if (c == 0.0) continue;
            const double *Kj = KY + j * size;
            for (ln_int i = 0; i < size; i++) out[i] += c * Kj[i];
        }
        for (ln_int i = 0; i < size; i++) out[i] = Y0[i] + h * out[i];
    }
}

/* Stage i's derivatives: dX/dt = U (10) and dU/dt = acc (9) into row i of KX, KU. */
static inline void store_stage(ln_int size, ln_int i, const double *U, const double *acc, double *KX, double *KU)
{
    for (ln_int j = 0; j < size; j++) {
        KX[i * size + j] = U[j];
        KU[i * size + j] = acc[j];
    }
}

static inline double weighted(const double *coef, ln_int n, const double *KY, ln_int size, ln_int i)
{
    double s = 0.0;
    for (ln_int j = 0; j < n; j++)
        if (coef[j] != 0.0) s += coef[j] * KY[j * size + i];
    return s;
}

/* The error norm over the free masses' coordinates; the mean is over 6 coordinates per free mass whatever
   DIM (in a plane the out-of-plane ones are zero and count as they do in 3-D). */
double FN(ln_rk_error_norm)(const ln_model *m, const ln_method *meth, const double *X, const double *U,
                            const double *Xn, const double *Un, const double *KX, const double *KU, double h)
{
    const ln_int size = m->K * DIM, n_weights = meth->n_stages + 1;
    const double n = 6.0 * (double)m->n_free;
    double s1 = 0.0, s2 = 0.0;
    for (int part = 0; part < 2; part++) {
        const double *Y0 = part == 0 ? X : U, *Y1 = part == 0 ? Xn : Un, *KY = part == 0 ? KX : KU;
        for (ln_int f = 0; f < m->n_free; f++) {
            const ln_int k = m->free_idx[f];
            for (int e = 0; e < DIM; e++) {
                const ln_int i = k * DIM + e;
                const double scale = meth->atol + meth->rtol * ln_fmax(fabs(Y0[i]), fabs(Y1[i]));
                if (meth->error_norm == LN_RMS_ERROR) {
                    const double err = h * weighted(meth->E1, n_weights, KY, size, i) / scale;
                    s1 += err * err;
                } else {
                    const double e5 = weighted(meth->E1, n_weights, KY, size, i) / scale;
                    const double e3 = weighted(meth->E2, n_weights, KY, size, i) / scale;
                    s1 += e5 * e5;
                    s2 += e3 * e3;
                }
            }
        }
    }
    if (meth->error_norm == LN_RMS_ERROR) return ln_sqrt(s1 / n);
    if (s1 == 0.0 && s2 == 0.0) return 0.0;
    return fabs(h) * s1 / ln_sqrt((s1 + 0.01 * s2) * n);
}

/* Hairer-Wanner's starting step (as scipy's select_initial_step), from f at (X, U) and at
   (X + h0 U, U + h0 acc0). */
static int starting_step(const ln_model *m, const ln_method *meth, ln_data *d, const double *X, const double *U,
                         const double *F_base, const double *acc0, double t, double span, double *h_out)
{
    const double n = 6.0 * (double)m->n_free;
    double d0 = 0.0, d1 = 0.0;
    for (ln_int f = 0; f < m->n_free; f++)
        for (int e = 0; e < DIM; e++) {
            const ln_int i = m->free_idx[f] * DIM + e;
            const double sx = meth->atol + meth->rtol * fabs(X[i]), su = meth->atol + meth->rtol * fabs(U[i]);
            d0 += (X[i] / sx) * (X[i] / sx) + (U[i] / su) * (U[i] / su);
            d1 += (U[i] / sx) * (U[i] / sx) + (acc0[i] / su) * (acc0[i] / su);
        }
    d0 = ln_sqrt(d0 / n);
    d1 = ln_sqrt(d1 / n);
    const double h0 = ln_trial_step(d0, d1, span);
    const ln_int size = m->K * DIM;
    for (ln_int i = 0; i < size; i++) {
        d->Xs[i] = X[i] + h0 * U[i];
        d->Us[i] = U[i] + h0 * acc0[i];
    }
    d->n_rhs++;
    int status;
    if (m->n_driven && (status = ln_drive_rows(m, d, t + h0, d->Xs, d->Us, d->F_base, DIM)) != LN_OK) return status;
    if (m->n_contacts) FN(ln_contacts_place)(m, d->Xs, d->Us);
    status = FN(stage_accelerations)(m, d, d->Xs, d->Us, F_base, d->acc1, d->T, 1);
    if (status != LN_OK) return status;
    double d2 = 0.0;
    for (ln_int f = 0; f < m->n_free; f++)
        for (int e = 0; e < DIM; e++) {
            const ln_int i = m->free_idx[f] * DIM + e;
            const double sx = meth->atol + meth->rtol * fabs(X[i]), su = meth->atol + meth->rtol * fabs(U[i]);
            const double dx = (d->Us[i] - U[i]) / sx, du = (d->acc1[i] - acc0[i]) / su;
            d2 += dx * dx + du * du;
        }
    d2 = ln_sqrt(d2 / n) / h0;
    *h_out = ln_starting_step(meth, h0, d1, d2, span);
    return LN_OK;
}

int FN(ln_rk_steps)(const ln_model *m, const ln_method *meth, ln_data *d, double *X, double *U,
                    const double *F_base, double *t_inout, double t_target, ln_int max_steps, ln_int *accepted)
{
    const ln_int size = m->K * DIM, s = meth->n_stages;
    double *KX = d->KX, *KU = d->KU, *Xs = d->Xs, *Us = d->Us, *Xn = d->Xn, *Un = d->Un, *acc = d->acc;
    double t = *t_inout;
    int status;
    *accepted = 0;
    if (m->n_ropes && (status = FN(ln_rope_start)(m, d, X, U, F_base, t)) != LN_OK) return status;
    d->n_rhs++;
    /* driven anchors are known functions of time: each stage's rows of X, U and of the base force (their
       accelerations) are set to the motion at the stage's time, t + c_i h */
    if (m->n_driven && (status = ln_drive_rows(m, d, t, X, U, d->F_base, DIM)) != LN_OK) return status;
    if (m->n_contacts) FN(ln_contacts_place)(m, X, U);
    if ((status = FN(stage_accelerations)(m, d, X, U, F_base, acc, d->T, 1)) != LN_OK) return status;
    store_stage(size, 0, U, acc, KX, KU);
    /* the longest step the sliding contacts' stiff mode allows; the controller's own h stands where it is shorter */
    double cap = FN(slip_step_cap)(m, meth, U, acc, d->T);
    ln_peaks_begin(m, d, t);
    if (d->h_next <= 0.0) {
        double h0;
        if ((status = starting_step(m, meth, d, X, U, F_base, acc, t, t_target - t, &h0)) != LN_OK) return status;
        d->h_next = h0;
    }
    while (t < t_target) {
        const double remaining = t_target - t;
        const double h = ln_controlled_step(ln_fmin(d->h_next, cap), t, t_target);
        if (h < 0.0) return LN_STEP_UNDERFLOW;
        double t_new = (h == remaining) ? t_target : t + h;
        /* the stages 1..s-1, then (row s: the weights b) the new point Xn, Un, whose evaluation also factors
           A(Xn), which the position projection below reuses */
        for (ln_int i = 1; i <= s; i++) {
            double *Yx = i < s ? Xs : Xn, *Yu = i < s ? Us : Un;
            combine(size, X, U, h, meth->AB + i * s, i, KX, KU, Yx, Yu);
            if (m->n_driven
                && (status = ln_drive_rows(m, d, i < s ? t + meth->C[i] * h : t_new, Yx, Yu, d->F_base, DIM)) != LN_OK)
                return status;
            if (m->n_contacts) FN(ln_contacts_place)(m, Yx, Yu);
            d->n_rhs++;
            if ((status = FN(stage_accelerations)(m, d, Yx, Yu, F_base, acc, d->T, 1)) != LN_OK) return status;
            store_stage(size, i, Yu, acc, KX, KU);
            if (m->n_ropes && i < s) FN(ln_rope_keep_stage)(m, d, i);
        }
        const double err = FN(ln_rk_error_norm)(m, meth, X, U, Xn, Un, KX, KU, h);
        if (!(err <= 1.0)) {  /* too large, or not finite */
            d->rejected++;
            d->h_next = ln_next_step_size(meth, h, d->h_next, err);
            continue;
        }
        /* positions onto (11) along the directions at Xn (unit vectors E1 of the last evaluation, A(Xn)
           factored), then the velocities onto (12) at the projected positions */
        status = m->n_contacts ? FN(ln_contacts_project)(m, meth, d, Xn, meth->position_tol)
                               : project_positions(m, d, Xn, d->E1, meth->position_tol, meth->max_projection_iter);
        if (status == LN_PROJECTION_FAILED) {
            /* the new point is too far off (11) for the projection: a step too long for the motion, rejected
               like one whose error estimate is too large (a shorter step lands closer to the manifold) */
            d->rejected++;
            d->h_next = h * meth->min_factor;
            continue;
        }
        if (status != LN_OK) return status;
        if (m->n_contacts) FN(ln_contacts_place)(m, Xn, Un);
        if ((status = project_velocities(m, d, Xn, Un, d->E1)) != LN_OK) return status;
        /* ropes: a step that holds an event ends just past it, in the new mode (stages/ropes.c) */
        if (m->n_ropes && (status = FN(ln_rope_step_events)(m, meth, d, X, U, F_base, t, Xn, Un, &t_new)) != LN_OK)
            return status;
        t = t_new;
        d->h_next = ln_next_step_size(meth, h, d->h_next, err);
        for (ln_int j = 0; j < size; j++) {
            X[j] = Xn[j];
            U[j] = Un[j];
        }
        *t_inout = t;
        ++*accepted;
        if (*accepted > max_steps) return LN_TOO_MANY_STEPS;
        if (t < t_target) {
            /* the first stage of the next step; A(X) is factored already (velocity projection), unless the ropes'
               events have factored others since */
            d->n_rhs++;
            if (m->n_contacts) FN(ln_contacts_place)(m, X, U);
            if ((status = FN(stage_accelerations)(m, d, X, U, F_base, acc, d->T, m->n_ropes != 0)) != LN_OK)
                return status;
            store_stage(size, 0, U, acc, KX, KU);
            cap = FN(slip_step_cap)(m, meth, U, acc, d->T);
        }
        /* d->T at the step's end: the next step's first stage, or after the last step its new point's (before the
           projections, which move it by about the step's local error) */
        ln_peaks_step(m, d, t);
    }
    ln_peaks_publish(m, d);
    return LN_OK;
}
