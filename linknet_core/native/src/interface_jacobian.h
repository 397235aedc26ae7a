/* Interface Jacobians (interface_jacobian.c): the exact derivatives of the instantaneous outputs (the tensions T of
 * (25)-(26), the force the network exerts on each anchor and the accelerations (9)) with respect to the inputs (the
 * external forces F and the driven anchors' P, V, A) at a fixed state X, U. What a co-simulation master's Jacobian
 * (fmi2GetDirectionalDerivative) asks for; the derivation is in linknet_core/dynamics/interface_jacobian.py, the
 * numpy reference of the same formulas, and docs/interface_jacobians.md.
 */
#ifndef LINKNET_INTERFACE_JACOBIAN_H
#define LINKNET_INTERFACE_JACOBIAN_H

#include "linknet.h"

typedef struct ln_interface ln_interface;   /* opaque: its own data (factorisation of A) and scratch */

/* A linearization workspace for model m (NULL: out of memory); it holds its own ln_data, so that the
   factorisation it keeps is never overwritten by an advance or an evaluation of the caller's data. */
LN_API ln_interface *ln_interface_new(const ln_model *m);
LN_API void ln_interface_free(ln_interface *J);

/* Linearize at the state X, U (K,3) with the input forces F_input (K,3; NULL: none; d->F_input for the held ones)
   and what the caller's data d holds: its time and its driven anchors' motion at d->t (their rows of X and U are
   set from it, as ln_evaluate does). With a frictionless ground the model's contacts' virtual anchors are placed
   from X, U here (their rows of X and U are not read); LN_NOT_LINEARIZABLE with a rough one (its grips). Evaluates the outputs there (the tensions, with the factorisation of A they
   need, kept in J). LN_OK, or ln_evaluate's status (then J is not prepared). d is only read. */
LN_API int ln_interface_prepare(const ln_model *m, ln_interface *J, const ln_data *d, const double *X,
                                const double *U, const double *F_input);

/* The derivative of the outputs along one seed at the state of the last ln_interface_prepare: dF (K,3) on the input
   forces (anchored rows ignored), dP, dV, dA (n_driven,3) on the driven anchors' position, velocity and
   acceleration; a NULL seed is zero. Writes dT (L), dFreact (n_fixed,3: the anchored masses in model order) and
   dacc (K,3), each skipped when NULL. One solve with the kept factorisation where A is regular, three where it is
   singular (minimum-norm tensions). LN_OK; LN_BAD_ARGUMENT when J was not prepared; LN_NON_FINITE when a result is
   not finite. */
LN_API int ln_interface_directional(const ln_model *m, ln_interface *J, const double *dF, const double *dP,
                                    const double *dV, const double *dA, double *dT, double *dFreact, double *dacc);

/* The force element kinds whose derivatives element_derivatives writes, by name: i = 0, 1, ... until NULL.
   linknet_core/native/interface.py checks them against the scene's FORCE_KINDS when it loads, so that a kind the
   core gains without a derivative here stops the first linearization instead of giving NaN. */
LN_API const char *ln_interface_kind_name(ln_int i);

/* Whether the last preparation found A singular (minimum-norm tensions: the pseudo-inverse's derivative). */
LN_API int ln_interface_singular(const ln_interface *J);

#endif
