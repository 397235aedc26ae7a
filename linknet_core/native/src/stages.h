/* Prototypes of the DIM-generic stages (src/stages/). No include guard: included once per DIM, with FN
   defined by the includer (dim.h in the stage files; data.c includes it for both DIMs). Vectors have DIM
   components: (K,DIM) and (L,DIM) arrays, row-major. */

/* stages/forces.c: F_k of (9) */
void FN(ln_scene_forces)(const ln_model *m, const double *X, const double *U, const double *F_base, double *F);

/* stages/tension.c: A of (25), B of (26) and their solution */
void FN(ln_unit_vectors)(const ln_model *m, const double *X, double *E);
int FN(ln_factor_tension_matrix)(const ln_model *m, ln_data *d, const double *E);
/* A(E) is singular (a pivot vanished): minimum-norm solves from here on, and the event counted. */
int FN(ln_factor_singular)(const ln_model *m, ln_data *d, const double *E);
void FN(ln_solve_tension_system)(const ln_model *m, ln_data *d, const double *b, double *x);
void FN(ln_add_correction)(const ln_model *m, const double *E, const double *mu, double scale, double *V);

/* stages/minnorm.c: minimum-norm solves where A is singular (redundant links, singular passages).
   factor: A(E) = C(E) M^-1 C(E)^T from the unit vectors E (L,DIM), as A of (25); LN_OK or LN_NO_MEMORY.
   solve: x = A^+ b (b, x of length L in link numbering; not the same array): the minimum-norm solution,
   which for a consistent b solves A x = b and has no component along the self-stresses (27), (31). */
int FN(ln_minnorm_factor)(const ln_model *m, ln_data *d, const double *E);
void FN(ln_minnorm_solve)(const ln_model *m, ln_data *d, const double *b, double *x);

/* stages/accelerations.c: dU/dt of (9) with the tensions of (25)-(26) */
int FN(ln_accelerations)(const ln_model *m, ln_data *d, const double *X, const double *U, const double *F_base,
                         double *acc, double *T, int refactor);

/* stages/projections.c: onto (11) and (12) */
int FN(ln_project_positions)(const ln_model *m, ln_data *d, double *Xc, const double *E_dir, double tol,
                             ln_int max_iter);
int FN(ln_project_velocities)(const ln_model *m, ln_data *d, const double *X, double *U, double *E);

/* stages/rattle.c: RATTLE and its compositions, n_steps equal steps from t_start to t_end on X, U in place */
int FN(ln_rattle_steps)(const ln_model *m, const ln_method *meth, ln_data *d, double *X, double *U,
                        const double *F_base, ln_int n_steps, double t_start, double t_end, ln_int *completed);

/* stages/runge_kutta.c: the embedded error estimate over the free masses' positions and velocities (stages KX,
   KU of (K,DIM) blocks, s + 1 of them), in the norm the method names; the mean is over 6 coordinates per free
   mass whatever DIM */
double FN(ln_rk_error_norm)(const ln_model *m, const ln_method *meth, const double *X, const double *U,
                            const double *Xn, const double *Un, const double *KX, const double *KU, double h);

/* stages/runge_kutta.c: embedded explicit Runge-Kutta with step-size control, projected after every step,
   from t to t_target on X, U in place (the last accepted state); *t and d->h_next are updated */
int FN(ln_rk_steps)(const ln_model *m, const ln_method *meth, ln_data *d, double *X, double *U,
                    const double *F_base, double *t, double t_target, ln_int max_steps, ln_int *accepted);

/* stages/ropes.c: scenes with ropes; mm is the mode's model (its inv_R is
   d->mode_inv_R: 0 on the slack ropes). start: the mode chosen from the state at the first advance, its mask in use.
   step_events: after an accepted step from (X0, U0) at t0 to (X1, U1) at *t1, the first event within it taken
   (the step then ends just past it, in the new mode). */
int FN(ln_rope_start)(const ln_model *mm, ln_data *d, double *X, double *U, const double *F_base, double t);
int FN(ln_rope_step_events)(const ln_model *mm, const ln_method *meth, ln_data *d, const double *X0, const double *U0,
                            const double *F_base, double t0, double *X1, double *U1, double *t1);
/* A ground: each contact's virtual anchor placed above its mass at (X, U) (U may be NULL), before any evaluation;
   the positions projected onto the mode's (11) and the ground, the anchors re-placed until the active contacts'
   gaps are within tol (their unit vectors at the result in d->E0, A factored). */
void FN(ln_contacts_place)(const ln_model *m, double *X, double *U);
int FN(ln_contacts_project)(const ln_model *mm, const ln_method *meth, ln_data *d, double *X, double tol);
/* Stage i (1 <= i < s) of an adaptive step's attempt has its tensions in d->T: the ropes' kept for step_events. */
void FN(ln_rope_keep_stage)(const ln_model *mm, ln_data *d, ln_int i);
/* A fixed-step method's step from (X, U) at t0 to t1 in place, with the events within it taken at their times. */
int FN(ln_rope_fixed_step)(const ln_model *mm, const ln_method *meth, ln_data *d, double *X, double *U,
                           const double *F_base, double t0, double t1);
