/* Free rigid bodies (engine_rigid.c): a scene whose every linked component is free, rigid and has a full
 * inertia tensor moves as rigid bodies. Each body's state is its centre of mass c, velocity v, orientation
 * quaternion q and body-frame angular momentum Pi; the masses' X, U follow from it:
 *     X_k = c + R r_k,   U_k = v + w x (R r_k),   w = R I^-1 Pi   (space frame),
 * r_k the mass's position in the body's principal axes, R the rotation of q (body -> space). The external
 * forces F_k of (9) act on a body through their resultant and their moment about c; the link tensions are
 * internal and cancel (31), so the point-mass machinery of (25)-(26) is not needed to move the bodies (the
 * tensions at an output come from ln_evaluate).
 *
 * ln_model.rigid points to the layout (which masses form which body, their body-frame offsets, inertia),
 * computed once in Python (principal axes, body frames); ln_data.rigid holds the body states and scratch.
 *
 * The body state of body b is row b of a (B,13) array: c (0:3), v (3:6), q = (w, x, y, z) (6:10), Pi (10:13).
 */
#ifndef LINKNET_RIGID_H
#define LINKNET_RIGID_H

#include "linknet.h"

/* How a body's free rotation is integrated, from its principal moments. */
enum ln_top {
    LN_SPHERICAL_TOP = 0,   /* I_1 = I_2 = I_3: exact, one rotation about Pi */
    LN_SYMMETRIC_TOP = 1,   /* I_1 = I_2 != I_3 (body axis 3 the distinct one): exact, two commuting rotations */
    LN_ASYMMETRIC_TOP = 2   /* three distinct moments: the symmetric DLM splitting */
};

#define LN_RIGID_STATE 13           /* numbers per body: c, v, q, Pi */

/* Fixed for a run: its fields are listed in ln_model_fields.h (LN_RIGID_MODEL_FIELDS), whence the Python binding's
   mirror (linknet_core/clib/library.py: RigidModel). */
struct ln_rigid_model {
    LN_DECLARE_FIELDS(LN_RIGID_MODEL_FIELDS)
};

/* Owned by ln_data; the body states and what a whole-interval advance needs, allocated once. */
/* The rigid path's scratch arrays, each listed once (allocated by ln_rigid_data_new, freed by ln_rigid_data_free):
   ARRAY(name, count), count an expression in the bodies B and the method's stages n_stages. */
#define LN_RIGID_DATA_ARRAYS(ARRAY)                                                                                 \
    ARRAY(Y, NY * B)                            /* (B,13) the body states */                                        \
    ARRAY(Y_start, NY * B)                      /* (B,13) where the last advance started (ln_rigid_restore) */      \
    ARRAY(R, 9 * B)                             /* (B,3,3) rotation matrices (row-major) of the current evaluation*/\
    ARRAY(f, 3 * B)                             /* (B,3) resultant */                                               \
    ARRAY(tau, 3 * B)                           /* (B,3) moment about c */                                          \
    ARRAY(w, 3 * B)                             /* (B,3) angular velocity */                                        \
    ARRAY(th, 3 * B)                            /* (B,3) rotation vector */                                         \
    ARRAY(v0, 3 * B)                            /* (B,3) the implicit half kick's iterates */                       \
    ARRAY(Pi0, 3 * B)                                                                                               \
    ARRAY(v_prev, 3 * B)                                                                                            \
    ARRAY(Pi_prev, 3 * B)                                                                                           \
    ARRAY(Ys, NY * B)                           /* (B,13) a Runge-Kutta stage */                                    \
    ARRAY(Yn, NY * B)                           /* (B,13) the new point */                                          \
    ARRAY(KY, (n_stages + 1) * NY * B)          /* (n_stages+1, B, 13) Runge-Kutta stage derivatives */

#define LN_RIGID_DATA_DECLARE(name, count) double *name;
struct ln_rigid_data {
    ln_int n_bodies;
    LN_RIGID_DATA_ARRAYS(LN_RIGID_DATA_DECLARE)
};
#undef LN_RIGID_DATA_DECLARE

LN_API struct ln_rigid_data *ln_rigid_data_new(const ln_model *m, ln_int n_stages);  /* stages of the method */
LN_API void ln_rigid_data_free(struct ln_rigid_data *r);

/* Advance the bodies from d->t to t_target with the base forces d->F_base (K,3; zero on anchors) held,
   the state-dependent forces (drag, springs) evaluated as they change; fixed-step compositions
   (method->gammas, steps of at most method->dt) or the embedded Runge-Kutta pair of the method (tableau,
   controller, d->h_next). Writes the masses' d->X, d->U at the end and the accepted steps into *steps.
   On a status other than LN_OK the caller restores X, U and calls ln_rigid_restore. Statuses: LN_OK,
   LN_NON_FINITE, LN_IMPLICIT_KICK_FAILED, LN_STEP_UNDERFLOW, LN_TOO_MANY_STEPS, LN_BAD_ARGUMENT (no bodies,
   a method of no known kind, more stages than ln_data_new was given). */
LN_API int ln_rigid_advance(const ln_model *m, const ln_method *meth, ln_data *d, double t_target, ln_int max_steps,
                     ln_int *steps);

/* Put the body states back to where the last ln_rigid_advance started. */
LN_API void ln_rigid_restore(const ln_model *m, ln_data *d);

/* The body states (B,13) into Y. */
LN_API void ln_rigid_get_state(const ln_model *m, const ln_data *d, double *Y);

/* Set the body states from Y (B,13), for a state set from outside (fitted to the masses in Python) or a
   snapshot, and write the masses' d->X, d->U from them. LN_BAD_ARGUMENT (nothing changed) if the model has
   no bodies, or Y has a non-finite number or a zero quaternion. */
LN_API int ln_rigid_set_state(const ln_model *m, ln_data *d, const double *Y);

/* n steps of exactly h of the method's Runge-Kutta tableau with no error control, the quaternion
   renormalised after each (order measurements). Moves d->t by n h, the bodies and d->X, d->U; d->h_next is
   left as it is. LN_OK, LN_NON_FINITE or LN_BAD_ARGUMENT (not a Runge-Kutta method, n < 1 or h <= 0). */
LN_API int ln_rigid_rk_fixed_steps(const ln_model *m, const ln_method *meth, ln_data *d, double h, ln_int n);

/* The layout of the bodies frozen at the mass state X, U (K,3) with masses mass (K) (anchors' entries unused): per
   body its mass, principal moments and top kind, its frame from the principal axes (right-handed; a symmetric
   top's distinct axis third, a spherical top the space axes), the masses' body-frame positions r about the centre
   of mass (in the frame of exactly the rotation matrix the steps use; zero off the bodies) and the initial body
   states Y0 (B,13). rigid gives n_bodies and body_of; its r, inertia, body_mass and kind are set to point to the
   arrays given here ((K,3), (B,3), (B), (B)), which are filled. LN_OK, or LN_BAD_ARGUMENT when a body has no mass.
   linknet_core.structure.bodies is the numpy reference (body_geometry, fit_bodies). */
LN_API int ln_rigid_layout(ln_int K, const double *mass, const double *X, const double *U, struct ln_rigid_model *rigid,
                           double *r, double *inertia, double *body_mass, ln_int *kind, double *Y0);

#endif
