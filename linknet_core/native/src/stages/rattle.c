/* RATTLE (Andersen 1983) and its symmetric compositions: velocity Verlet with the links enforced every step.
 *
 * One RATTLE step of size h from (X, U), with A(X) factored:
 *   U_half = U + h/2 M^-1 F(X, U)                        half kick
 *   X_new  = X + h U_half + M^-1 C(X)^T mu   on (11)     drift, then the position stage (projections.c)
 *   U_half = (X_new - X) / h
 *   U_new  = U_half + h/2 M^-1 F(X_new, U_half), projected onto (12) at X_new
 * The velocity U_half after the position stage is taken from the stage's correction itself, not from the rounded
 * X_new - X (velocity_after_position_stage): that keeps the coordinates' round-off out of the velocity.
 * With velocity-dependent forces (drag, dampers, a sliding contact's Coulomb friction on a ground) the second half
 * kick is implicit in U_new (fixed-point iteration), which keeps the step symmetric and so second order. A
 * composition takes RATTLE steps of gamma_i h in turn (method->gammas); the velocity projection's factorisation at
 * X_new is the next stage's A(X). A step whose position stage cannot converge is split into equal sub-steps
 * (split_step). With ropes or a ground each stage's midpoint, X + h/2 U_half, is where the forces inside a step are
 * sampled (rope_keep_midpoint): RATTLE has no other state inside its step.
 */
#include <math.h>

#include "../dim.h"
#include "../drive.h"
#include "../linknet.h"
#include "../ln_math.h"
#include "../stages.h"
#include "../tension_peaks.h"

LN_SCALAR_LOOPS_BEGIN

#define IMPLICIT_KICK_ITERATIONS 60

/* A ground (stages/ropes.c, stages/friction.c, later in this translation unit) */
static inline int FN(any_sliding)(const ln_model *mm);
static int FN(forces_with_friction)(const ln_model *mm, ln_data *d, const double *X, const double *U, const double *F,
                                    double *out, int refactor);
static void FN(contacts_pad_velocity)(const ln_model *m, double *V);
static int FN(contacts_project_along)(const ln_model *mm, const ln_method *meth, ln_data *d, double *Xc,
                                      const double *E_dir, double tol);
/* ropes (stages/ropes.c): the forces at a stage's midpoint kept for the screen of the forces inside a step */
static int FN(rope_keep_midpoint)(const ln_model *mm, ln_data *d, ln_int j, double node, double t_mid, const double *X,
                                  double *U_mid, double hs, const double *F_base);

/* Forces at (X, U): the base forces, or with drag and springs added into scratch. */
static inline const double *rattle_forces(const ln_model *m, ln_data *d, const double *X, const double *U,
                                          const double *F_base)
{
    if (m->n_elements == 0) return F_base;
    FN(ln_scene_forces)(m, X, U, F_base, d->F);
    return d->F;
}

/* The forces a kick takes at (X, U) into *F: rattle_forces, and on a ground where a contact slides in the mode its
   friction -mu N d too, which depends on U (ModeDynamics.forces; the contacts' anchors placed at (X, U)). refactor:
   whether A(X) must be factored for the friction's solves (0: the factorisation at hand is at X). */
static inline int kick_forces(const ln_model *m, ln_data *d, const double *X, const double *U, const double *F_base,
                              int refactor, const double **F)
{
    if (!(m->n_grips && FN(any_sliding)(m))) {
        *F = rattle_forces(m, d, X, U, F_base);
        return LN_OK;
    }
    *F = d->F;
    return FN(forces_with_friction)(m, d, X, U, F_base, d->F, refactor);
}

/* The scene's masses' coordinates: the contacts' and grips' virtual anchors come after them. */
static inline ln_int scene_coordinates(const ln_model *m) { return (m->K - m->n_contacts - m->n_grips) * DIM; }

/* U_half after the position stage of a RATTLE stage of size hs: the drift's U_half plus the position stage's
   correction M^-1 C(X)^T mu over hs (seed (9), (11)). The correction is not read off as X_new - X_drift: both are
   coordinates of size |X|, so that difference carries the rounding of every update of X_new, ulp(|X|), in every
   direction; divided by hs it enters the velocity as ulp(|X|) / hs each stage, its part along the manifold survives
   the velocity projection, and over N steps the positions drift like ulp(|X|) N^1.5: the error grew as dt shrank
   and with the scene's distance from the origin (benchmarks/roundoff.py). The correction's own part is its component
   along M^-1 C(X)^T, the normal part of X_new - X_drift in the mass metric, M^-1 C^T A^-1 C (X_new - X_drift) with
   A(X) (25) still factored from the stage's start: what is left of the rounding there is along the links, which
   the velocity projection removes. One solve on the factorisation at hand. Where the position stage needed exact
   Newton or Gauss-Newton (the factorisation may no longer be A(X)), the difference X_new - X over hs.
   Anchored masses (inv_m = 0; driven anchors move where the drive puts them) keep (X_new - X) / hs, their mean
   velocity over the stage. */
LN_ALWAYS_INLINE void velocity_after_position_stage(const ln_model *m, ln_data *d, const double *X, const double *Xc,
                                                    const double *E0, double hs, int factored_at_X, double *Uh)
{
    const ln_int K = m->K;
    if (!factored_at_X || m->L == 0) {
        for (ln_int i = 0; i < K * DIM; i++) Uh[i] = (Xc[i] - X[i]) / hs;
        return;
    }
    /* the stage's shift X_new - X_drift, in place of X_drift; on a ground padded as ModeDynamics pads a velocity (a
       contact's virtual anchor moves with its mass along the plane, the grips' stay): the anchors' own coordinates,
       re-placed above the masses, would bring their rounding back */
    double *shift = d->X_drift;
    for (ln_int i = 0; i < K * DIM; i++) shift[i] = Xc[i] - shift[i];
    if (m->n_contacts) FN(contacts_pad_velocity)(m, shift);
    double *rhs = d->phi, *mu = d->mu;
    for (ln_int l = 0; l < m->L; l++) {
        const ln_int a = m->k1[l], b = m->k2[l];
        double s = 0.0;
        for (int e = 0; e < DIM; e++) s += E0[l * DIM + e] * (shift[a * DIM + e] - shift[b * DIM + e]);
        rhs[l] = s;
    }
    FN(ln_solve_tension_system)(m, d, rhs, mu);
    for (ln_int k = 0; k < K; k++)
        if (m->inv_m[k] == 0.0)
            for (int e = 0; e < DIM; e++) Uh[k * DIM + e] = (Xc[k * DIM + e] - X[k * DIM + e]) / hs;
    FN(ln_add_correction)(m, E0, mu, 1.0 / hs, Uh);
}

/* One step of size h from t to t_end: the composition's RATTLE stages in turn, with A(X) factored at *E0 on
   entry and, on success, at the new X on exit (the pointers swap with every stage). Driven anchors: each stage's
   position stage targets their P at the stage's end and its velocity stage their V there (drive.c). On a ground
   (a mode of stages/ropes.c with contacts) every evaluation first places the contacts' virtual anchors at the
   state it is made at (ln_contacts_place), the position stage re-places them until the contacts are on the plane
   (contacts_project_along), and a sliding contact's friction is a force of the kicks, implicit in the second.
   sample (ropes, the step of ln_rope_fixed_step): each stage's midpoint, X + hs/2 U_half with the half kick's
   velocity, its forces kept for the screen of the forces inside the step (rope_keep_midpoint). */
LN_ALWAYS_INLINE int composition_step(const ln_model *m, const ln_method *meth, ln_data *d, double *X, double *U,
                            const double *F_base, double h, double t, double t_end, double **E0_inout,
                            double **E1_inout, int sample)
{
    const ln_int K = m->K, scene_size = scene_coordinates(m);
    const double *inv_m = m->inv_m;
    double *E0 = *E0_inout, *E1 = *E1_inout, *Uh = d->Uh, *Xc = d->Xc, *U_iterate = d->U_iterate;
    const int ground = m->n_contacts > 0;
    int status;
    double fraction = 0.0;
    for (ln_int g = 0; g < meth->n_gammas; g++) {
        const double hs = meth->gammas[g] * h, stage_start = t + fraction * h;
        fraction += meth->gammas[g];
        const double stage_end = g == meth->n_gammas - 1 ? t_end : t + fraction * h;
        const double *F;
        if (ground) FN(ln_contacts_place)(m, X, U);
        if ((status = kick_forces(m, d, X, U, F_base, 0, &F)) != LN_OK) return status;
        for (ln_int k = 0; k < K; k++)
            for (int e = 0; e < DIM; e++) {
                const ln_int i = k * DIM + e;
                Uh[i] = U[i] + 0.5 * hs * inv_m[k] * F[i];
                Xc[i] = X[i] + hs * Uh[i];
            }
        if (sample)  /* the midpoint's velocity, kept through the position stage (which leaves d->Us alone) */
            for (ln_int i = 0; i < K * DIM; i++) d->Us[i] = Uh[i];
        if (m->n_driven && (status = ln_drive_rows(m, d, stage_end, Xc, NULL, NULL, DIM)) != LN_OK) return status;
        for (ln_int i = 0; i < K * DIM; i++) d->X_drift[i] = Xc[i];
        /* position stage: Xc + M^-1 C(X)^T mu on (11), simplified Newton with A(X) factored */
        const ln_int newton_projections = d->exact_newton_projections;
        status = ground ? FN(contacts_project_along)(m, meth, d, Xc, E0, meth->position_tol)
                        : project_positions(m, d, Xc, E0, meth->position_tol, meth->max_projection_iter);
        if (status != LN_OK) return status;
        velocity_after_position_stage(m, d, X, Xc, E0, hs, newton_projections == d->exact_newton_projections, Uh);
        /* the stage's midpoint: its forces need A factored there, and A(X) is done with (the kick below and the
           velocity projection factor their own) */
        const double t_mid = stage_start + 0.5 * (stage_end - stage_start);
        if (sample && (status = FN(rope_keep_midpoint)(m, d, g, (t_mid - t) / h, t_mid, X, d->Us, hs, F_base)) != LN_OK)
            return status;
        /* second half kick, then the velocity projection onto (12) at the new positions */
        if (ground) FN(ln_contacts_place)(m, Xc, Uh);
        if ((status = kick_forces(m, d, Xc, Uh, F_base, 1, &F)) != LN_OK) return status;
        for (ln_int k = 0; k < K; k++)
            for (int e = 0; e < DIM; e++) {
                const ln_int i = k * DIM + e;
                U[i] = Uh[i] + 0.5 * hs * inv_m[k] * F[i];
                X[i] = Xc[i];
            }
        if (m->n_driven && (status = ln_drive_rows(m, d, stage_end, NULL, U, NULL, DIM)) != LN_OK) return status;
        if (ground) FN(contacts_pad_velocity)(m, U);
        if ((status = project_velocities(m, d, X, U, E1)) != LN_OK) return status;
        const int sliding = m->n_grips && FN(any_sliding)(m);
        if (m->velocity_dependent || sliding) {
            /* U_new = P(U_half + hs/2 M^-1 F(X_new, U_new)): contraction factor ~ hs c / (2 m) for a damping c, and
               ~ hs mu N / (2 m |v_t|) for a sliding contact's friction, which a slow slip (its first steps from rest)
               takes above 1. With friction alone an iteration that stops contracting ends with its first iterate
               (the kick with the forces at the explicit kick's velocity, whose error O(hs^2) keeps the step second
               order; Rattle._implicit_kick's stiff_ok) */
            const int stiff_ok = !m->velocity_dependent;
            double *first = d->Us, last_change = INFINITY;
            int converged = 0, stalled = 0;
            for (int it = 0; it < IMPLICIT_KICK_ITERATIONS && !converged && !stalled; it++) {
                if (ground) FN(contacts_pad_velocity)(m, U);
                if ((status = kick_forces(m, d, X, U, F_base, 0, &F)) != LN_OK) return status;
                for (ln_int k = 0; k < K; k++)
                    for (int e = 0; e < DIM; e++) {
                        const ln_int i = k * DIM + e;
                        U_iterate[i] = Uh[i] + 0.5 * hs * inv_m[k] * F[i];
                    }
                if (m->n_driven && (status = ln_drive_rows(m, d, stage_end, NULL, U_iterate, NULL, DIM)) != LN_OK)
                    return status;
                if (ground) FN(contacts_pad_velocity)(m, U_iterate);
                if ((status = FN(ln_project_velocities)(m, d, X, U_iterate, E1)) != LN_OK) return status;
                double change = 0.0, size = 0.0;
                for (ln_int i = 0; i < scene_size; i++) {
                    change = ln_fmax(change, fabs(U_iterate[i] - U[i]));
                    size = ln_fmax(size, fabs(U_iterate[i]));
                }
                for (ln_int i = 0; i < K * DIM; i++) U[i] = U_iterate[i];
                if (it == 0 && stiff_ok)
                    for (ln_int i = 0; i < K * DIM; i++) first[i] = U[i];
                converged = change <= 4e-16 * size || change == 0.0;
                stalled = !converged && stiff_ok && change >= last_change;
                last_change = change;
            }
            if (!converged) {
                if (!stiff_ok) return LN_IMPLICIT_KICK_FAILED;
                for (ln_int i = 0; i < K * DIM; i++) U[i] = first[i];
            }
        }
        if (ground) FN(contacts_pad_velocity)(m, U);
        double *swap = E0;  /* the factorisation at the new X is the next stage's A(X) */
        E0 = E1;
        E1 = swap;
        *E0_inout = E0;
        *E1_inout = E1;
    }
    return LN_OK;
}

/* A step whose position stage (or implicit half kick) fails is taken again from its start as 2, 4, ...
   equal sub-steps, each the whole composition (so each keeps the method's symmetry), at most
   2^ln_max_split_level of them: a whipping tip that moves too far within one step for Newton to converge
   moves little enough within a sub-step, and the result keeps the method's order as dt shrinks. The numpy
   reference reads the bound from here (linknet_core.integrators.base.MAX_SPLIT_LEVEL) and splits the same way. */
#ifndef LINKNET_MAX_SPLIT_LEVEL
#define LINKNET_MAX_SPLIT_LEVEL
LN_API extern const int ln_max_split_level;
#if DIM == 3
LN_API const int ln_max_split_level = 6;
#endif
#endif

LN_NOINLINE int split_step(const ln_model *m, const ln_method *meth, ln_data *d, double *X, double *U,
                      const double *F_base, double h, double t, double t_end, double **E0, double **E1, int status)
{
    const ln_int size = m->K * DIM;
    for (int level = 1; level <= ln_max_split_level; level++) {
        const ln_int parts = (ln_int)1 << level;
        for (ln_int i = 0; i < size; i++) {
            X[i] = d->X_step[i];
            U[i] = d->U_step[i];
        }
        FN(ln_unit_vectors)(m, X, *E0);
        if ((status = FN(ln_factor_tension_matrix)(m, d, *E0)) != LN_OK) return status;
        status = LN_OK;
        const double hp = h / (double)parts;
        for (ln_int part = 0; part < parts && status == LN_OK; part++)
            status = composition_step(m, meth, d, X, U, F_base, hp, t + (double)part * hp,
                                      part == parts - 1 ? t_end : t + (double)(part + 1) * hp, E0, E1, 0);
        if (status == LN_OK) {
            d->split_steps++;
            if (parts > d->finest_split) d->finest_split = parts;
            return LN_OK;
        }
        if (status != LN_PROJECTION_FAILED && status != LN_IMPLICIT_KICK_FAILED) return status;
    }
    return status;
}

#if DIM == 3
/* On a scene with ropes or a ground each RATTLE stage's midpoint of a fixed step is a row of its node and the ropes'
   tensions in ln_data.stage_tensions (rope_keep_midpoint): n_gammas (n_ropes + 1) values, within the room of
   2 n_gammas stages of n_ropes each. */
ln_int ln_midpoint_rows(const ln_model *m, const ln_method *meth)
{
    return meth->kind == LN_COMPOSITION && m->n_ropes ? 2 * meth->n_gammas : 0;
}
#endif

/* A step that failed for good: the tensions at its start into d->T, from which the failure's message estimates the
   fastest oscillation of the masses between their links (linknet_core.dynamics.equations.fastest_oscillation)
   and so whether the step is beyond the stability limit of explicit steps. 0 where they cannot be evaluated. */
LN_COLD void record_failed_step_tensions(const ln_model *m, ln_data *d, const double *F_base)
{
    if (FN(ln_accelerations)(m, d, d->X_step, d->U_step, F_base, d->acc, d->T, 1) != LN_OK)
        for (ln_int l = 0; l < m->L; l++) d->T[l] = 0.0;
}

/* T (25)-(26) at (X, U) and time t into d->T, for the located peaks (tension_peaks.h), on A(X) as it stands factored
   (at a step's end the velocity projection's, at the interval's start the start's): B of (26) and one solve, no
   factorisation. The forces are the scene's at (X, U), a driven anchor's row of the base force its acceleration at t
   (as the Runge-Kutta stages take them); E: scratch (L,DIM) for the unit vectors. */
static int tensions_at(const ln_model *m, ln_data *d, const double *X, const double *U, const double *F_base, double t,
                       double *E)
{
    if (m->L == 0) return LN_OK;
    int status;
    if (m->n_driven && (status = ln_drive_rows(m, d, t, NULL, NULL, d->F_base, DIM)) != LN_OK) return status;
    const double *F = rattle_forces(m, d, X, U, F_base);
    double *B = d->B;
    for (ln_int l = 0; l < m->L; l++) link_terms(m, X, U, F, l, E, &B[l]);
    FN(ln_solve_tension_system)(m, d, B, d->T);
    return LN_OK;
}

int FN(ln_rattle_steps)(const ln_model *m, const ln_method *meth, ln_data *d, double *X, double *U,
                        const double *F_base, ln_int n_steps, double t_start, double t_end, ln_int *completed)
{
    const ln_int size = m->K * DIM;
    const double h = (t_end - t_start) / (double)n_steps;
    double *E0 = d->E0, *E1 = d->E1;
    int status;
    *completed = 0;
    if (m->n_ropes && (status = FN(ln_rope_start)(m, d, X, U, F_base, t_start)) != LN_OK) return status;
    FN(ln_unit_vectors)(m, X, E0);
    if (m->L > 0 && (status = FN(ln_factor_tension_matrix)(m, d, E0)) != LN_OK) return status;
    if ((status = tensions_at(m, d, X, U, F_base, t_start, E1)) != LN_OK) return status;
    ln_peaks_begin(m, d, t_start);
    for (ln_int step = 0; step < n_steps; step++) {
        for (ln_int i = 0; i < size; i++) {
            d->X_step[i] = X[i];
            d->U_step[i] = U[i];
        }
        /* the last step ends on t_end itself: the driven anchors' final position */
        const double t = t_start + (double)step * h;
        const double end = step == n_steps - 1 ? t_end : t_start + (double)(step + 1) * h;
        if (m->n_ropes) {
            /* ropes: the step taken to each event within it and finished in the new mode (stages/ropes.c), then A
               factored at its end again for the tensions below */
            status = FN(ln_rope_fixed_step)(m, meth, d, X, U, F_base, t, end);
            if (status == LN_OK) {
                FN(ln_unit_vectors)(m, X, E0);
                status = FN(ln_factor_tension_matrix)(m, d, E0);
            }
        } else {
            status = composition_step(m, meth, d, X, U, F_base, h, t, end, &E0, &E1, 0);
            if (status == LN_PROJECTION_FAILED || status == LN_IMPLICIT_KICK_FAILED)
                status = split_step(m, meth, d, X, U, F_base, h, t, end, &E0, &E1, status);
        }
        if (status == LN_PROJECTION_FAILED) record_failed_step_tensions(m, d, F_base);
        if (status != LN_OK) return status;
        double total = 0.0;
        for (ln_int i = 0; i < size; i++) total += X[i] + U[i];
        if (!isfinite(total)) return LN_NON_FINITE;
        /* the step's velocity projection left A at the new X factored (its unit vectors in E0): E1 is free */
        if ((status = tensions_at(m, d, X, U, F_base, end, E1)) != LN_OK) return status;
        ln_peaks_step(m, d, end);
        *completed = step + 1;
    }
    ln_peaks_publish(m, d);
    return LN_OK;
}

LN_SCALAR_LOOPS_END
