/* The fields of ln_data, the core's mutable struct, each written once, as ln_model_fields.h lists the constant ones.
 *
 * From this list linknet.h declares ln_data, data.c allocates, resets and frees it, and model_fields.c adds it to
 * the table of fields the library exports, from which the Python binding builds its mirror of ln_data
 * (linknet_core/clib/library.py). Adding an array is one line here, plus the code that uses it.
 *
 * The list takes one macro per way a field lives:
 *   SCALAR(type, name)           type name;   zero in a new data, and again after ln_data_reset
 *   KEPT(type, name)             type name;   set once (by ln_data_new, or by whoever owns the data) and kept by
 *                                ln_data_reset: a setting, or the size of an allocation
 *   ARRAY(type, name, count)     type *name;  count entries allocated and zeroed by ln_data_new, zeroed by
 *                                ln_data_reset, freed by ln_data_free. count is an expression in the model `m`
 *                                and the data's KEPT fields through `s`, as ln_model_fields.h's counts are
 *   OWNED(type, name, release)   type *name;  an object of the data's own, made where it is first needed (or by
 *                                ln_data_new when the model needs it), kept by ln_data_reset and freed by
 *                                ln_data_free with release(name), which takes NULL
 *   BORROWED(type, name)         type *name;  what the data's user plugs in and keeps: NULL in a new data and after
 *                                ln_data_reset, never freed
 * where the type of a SCALAR, KEPT or ARRAY field is one of ln_int, int, double, uint8_t (LN_FIELD_CODE gives its code).
 * What a new data holds beyond zeros (the first motion of the driven anchors, ...) is data.c's initial_values.
 */
#ifndef LINKNET_DATA_FIELDS_H
#define LINKNET_DATA_FIELDS_H

#define LN_EVENT_LOG 4096  /* the events one data keeps between two drains */

#define LN_DATA_FIELDS(SCALAR, KEPT, ARRAY, OWNED, BORROWED)                                                        \
    /* the state */                                                                                                 \
    SCALAR(double, t)                                                                                               \
    ARRAY(double, X, 3 * m->K)                          /* (K,3) */                                                 \
    ARRAY(double, U, 3 * m->K)                          /* (K,3) */                                                 \
    ARRAY(double, F_input, 3 * m->K)                    /* (K,3) held input force; rows of anchored masses are      \
                                                           ignored */                                               \
    /* the integrator's internals */                                                                                \
    SCALAR(double, h_next)                              /* adaptive methods: next step (0: choose the starting      \
                                                           step) */                                                 \
    SCALAR(int, planar)                                 /* 1 while the 2-D path is used (a planar scene until it    \
                                                           left the plane) */                                       \
    SCALAR(ln_int, steps)                               /* steps, rejected, n_rhs: accumulated over the run */      \
    SCALAR(ln_int, rejected)                                                                                        \
    SCALAR(ln_int, n_rhs)                                                                                           \
    SCALAR(ln_int, split_steps)                         /* fixed steps split into sub-steps because their position  \
                                                           stage failed */                                          \
    SCALAR(ln_int, finest_split)                        /* the most sub-steps one step was split into */            \
    SCALAR(ln_int, last_steps)                          /* steps of the last advance */                             \
    /* diagnostics of the last failure */                                                                           \
    SCALAR(int, status)                                                                                             \
    SCALAR(ln_int, fail_link)                           /* worst link of a failed projection, or -1 */              \
    SCALAR(double, fail_residual)                       /* relative residual reached */                             \
    SCALAR(double, fail_before)                         /* relative residual before the projection */               \
    SCALAR(ln_int, fail_iterations)                                                                                 \
    SCALAR(double, fail_t)                              /* time of the last accepted state */                       \
    SCALAR(double, fail_floor)                          /* relative round-off floor the failed projection's last    \
                                                           step allowed */                                          \
    SCALAR(double, floor_reached)                       /* largest relative residual at which a projection stopped  \
                                                           on its floor */                                          \
    SCALAR(ln_int, floor_stops)                         /* position projections stopped at their round-off floor    \
                                                           above the tolerance */                                   \
    /* the last evaluation's tensions, accelerations and anchor reactions */                                        \
    ARRAY(double, T, m->L)                              /* (L); after an advance of a composition that failed with  \
                                                           LN_PROJECTION_FAILED: the tensions at the start of the   \
                                                           step that failed */                                      \
    ARRAY(double, acc, 3 * m->K)                        /* (K,3) */                                                 \
    ARRAY(double, reaction, 3 * m->n_fixed)             /* (n_fixed,3) the force the network exerts on each anchor  \
                                                           (ln_evaluate) */                                         \
    ARRAY(double, T_peak, m->L)                         /* (L) largest |T_l| of the last advance, signed: */        \
    ARRAY(double, T_peak_time, m->L)                    /* (L) and when, s (tension_peaks.c) */                     \
    ARRAY(double, T_history, 2 * m->L)                  /* (2,L) T at its last two step ends, older first */        \
    ARRAY(double, peak_work, 2 * m->L)                  /* (2,L) its peaks and times so far, published on success */\
    SCALAR(double, history_t0)                          /* their times, s */                                        \
    SCALAR(double, history_t1)                                                                                      \
    SCALAR(ln_int, history_points)                      /* step ends taken in the last advance; 0: none located */  \
    /* driven anchors (drive.c): scene motions run in scene time t - drive_t0; input-driven anchors follow the      \
       held quadratic P + V s + A s^2/2, s = t - drive_hold_t (rows of drive_P, drive_V, drive_A), or, when         \
       drive_callback is set, what it writes for them at t: P, V, A of each input-driven anchor in turn (9 values   \
       per anchor); it returns 0 on success, and is called with drive_user. */                                      \
    KEPT(double, drive_t0)                              /* the scene's time origin: the data's setting */           \
    SCALAR(double, drive_hold_t)                        /* drive_t0 in a new or reset data */                       \
    ARRAY(double, drive_P, 3 * m->n_driven)             /* (n_driven,3) */                                          \
    ARRAY(double, drive_V, 3 * m->n_driven)                                                                         \
    ARRAY(double, drive_A, 3 * m->n_driven)                                                                         \
    BORROWED(ln_drive_motion, drive_callback)                                                                       \
    BORROWED(void, drive_user)                                                                                      \
    ARRAY(double, impulse, 3 * m->n_driven)             /* (n_driven,3) what the links gave each driven anchor in   \
                                                           impulses over the last advance, N s: the jump's at its   \
                                                           start and, with ropes, every event's in it */            \
    ARRAY(double, jump_impulse, 3 * m->n_driven)        /* (n_driven,3) the part of it of the jump alone */         \
    SCALAR(double, jump_position)                       /* the last advance's anchor jump: largest coordinate       \
                                                           change, 0 if none */                                     \
    SCALAR(double, jump_velocity)                                                                                   \
    SCALAR(ln_int, jumps)                               /* advances that started with a jump of the anchors         \
                                                           (counted over the run) */                                \
    /* scratch (sized for DIM = 3; the 2-D path uses the first 2K or 2L entries) */                                 \
    ARRAY(double, X_start, 3 * m->K)                    /* (K,3) the state at the start of an advance               \
                                                           (all-or-nothing) */                                      \
    ARRAY(double, U_start, 3 * m->K)                                                                                \
    ARRAY(double, X_step, 3 * m->K)                     /* (K,3) the state at the start of a fixed step (for        \
                                                           splitting it) */                                         \
    ARRAY(double, U_step, 3 * m->K)                                                                                 \
    ARRAY(double, Xp, 2 * m->K)                         /* (K,2) the state and base force in the plane's            \
                                                           coordinates */                                           \
    ARRAY(double, Up, 2 * m->K)                                                                                     \
    ARRAY(double, Fp, 2 * m->K)                                                                                     \
    ARRAY(double, F_base, 3 * m->K)                     /* (K,3) each, to X_drift */                                \
    ARRAY(double, F, 3 * m->K)                                                                                      \
    ARRAY(double, Uh, 3 * m->K)                                                                                     \
    ARRAY(double, Xc, 3 * m->K)                                                                                     \
    ARRAY(double, U_iterate, 3 * m->K)                                                                              \
    ARRAY(double, acc1, 3 * m->K)                                                                                   \
    ARRAY(double, Xs, 3 * m->K)                                                                                     \
    ARRAY(double, Us, 3 * m->K)                                                                                     \
    ARRAY(double, Xn, 3 * m->K)                                                                                     \
    ARRAY(double, Un, 3 * m->K)                                                                                     \
    ARRAY(double, X_drift, 3 * m->K)                    /* a RATTLE stage's drift X + h U_half, before its position \
                                                           stage */                                                 \
    ARRAY(double, E0, 3 * m->L)                         /* (L,3) unit vectors */                                    \
    ARRAY(double, E1, 3 * m->L)                                                                                     \
    ARRAY(double, B, m->L)                              /* (L) each, to work */                                     \
    ARRAY(double, mu, m->L)                                                                                         \
    ARRAY(double, phi, m->L)                                                                                        \
    ARRAY(double, scale, m->L)                                                                                      \
    ARRAY(double, work, m->L)                                                                                       \
    ARRAY(double, KX, (s->n_stages_allocated + 1) * 3 * m->K)  /* ((s+1),K,3) Runge-Kutta stages */                 \
    ARRAY(double, KU, (s->n_stages_allocated + 1) * 3 * m->K)                                                       \
    KEPT(ln_int, n_stages_allocated)                                                                                \
    /* the factorisation of A */                                                                                    \
    ARRAY(double, pair_values, m->n_pairs)              /* (n_pairs) the entries of A (25), pair by pair */         \
    OWNED(struct ln_ldl_numeric, ldl, ln_ldl_numeric_free)  /* LN_SOLVER_LDL */                                     \
    ARRAY(double, chain_sub, m->L)                      /* (L) LN_SOLVER_CHAIN: Thomas' elimination in path order */\
    ARRAY(double, chain_Dinv, m->L)                                                                                 \
    SCALAR(int, singular)                               /* the last factorisation met a vanishing pivot:            \
                                                           minimum-norm solves */                                   \
    SCALAR(ln_int, singular_events)                     /* factorisations that switched to the minimum-norm path */ \
    OWNED(double, krylov, free)                         /* the exact-Newton position stage's Krylov basis, of       \
                                                           krylov_size entries */                                   \
    KEPT(ln_int, krylov_size)                                                                                       \
    SCALAR(ln_int, exact_newton_projections)            /* position stages that needed exact Newton */              \
    OWNED(struct ln_minnorm_work, minnorm, ln_minnorm_free)                                                         \
    OWNED(struct ln_rigid_data, rigid, ln_rigid_data_free)  /* free rigid bodies (ln_model.rigid) */                \
    ARRAY(double, drive_scratch, 18 * m->n_driven)      /* P, V, A (n_driven,3 each) of the anchors at a time, then \
                                                           the callback's 9 values per anchor */ \
    /* ropes (stages/ropes.c): the mode is part of the state (an FMU state copies it); the events of the advances  \
       since the log was last drained (ln_rope_events_drained), and each rope's impulse summed over the last       \
       advance. None of it is allocated beyond one entry where the model has no ropes */                           \
    ARRAY(uint8_t, link_active, m->n_ropes ? m->L : 0)  /* (L) 1 for rods and taut ropes: the mode; on a grip link \
                                                           (ln_model.n_grips) 1 while its contact sticks */         \
    ARRAY(double, slip_reference, 3 * m->n_grips / 2)   /* (n_contacts,3) with friction: each sliding contact's     \
                                                           slip direction at the step's start (zero: none; part of  \
                                                           the state, UnilateralDynamics.slip_reference) */         \
    ARRAY(double, friction_work, m->n_grips ? 15 * m->K + (3 * m->n_contacts + 2) * m->L                          \
                                 + 7 * m->n_contacts * m->n_contacts + 20 * m->n_contacts : 0)  /* stages/friction.c */\
    ARRAY(ln_int, friction_index, m->n_grips ? 3 * m->n_contacts : 0)                                              \
    ARRAY(uint8_t, friction_flags, m->n_grips ? 6 * m->n_contacts : 0)  /* (6, n_contacts) sets of contacts */     \
    ARRAY(double, friction_values, m->n_grips ? 6 * m->n_contacts : 0)  /* (6, n_contacts) per-contact values */   \
    SCALAR(int, mode_chosen)                            /* 0 until the first advance chooses the mode */            \
    SCALAR(ln_int, events_this_step)                    /* consecutive accepted steps that ended at an event */     \
    ARRAY(double, rope_impulse, m->n_ropes ? m->L : 0)  /* (L) N s: each rope's impulse over the last advance */    \
    SCALAR(ln_int, n_events)                            /* events in the log */                                     \
    SCALAR(ln_int, events_lost)                         /* events beyond the log's capacity, not kept */            \
    ARRAY(double, event_t, m->n_ropes ? LN_EVENT_LOG : 0)     /* the log: time, s */                                \
    ARRAY(ln_int, event_kind, m->n_ropes ? LN_EVENT_LOG : 0)  /* enum ln_event_kind */                              \
    ARRAY(ln_int, event_link, m->n_ropes ? LN_EVENT_LOG : 0)  /* the rope's link, 0-based */                        \
    ARRAY(double, event_impulse, m->n_ropes ? LN_EVENT_LOG : 0)  /* N s (0 for slack) */                            \
    /* ropes' scratch: the mode's 1/R_l (0 on a slack rope: its unit vector, term of (26) and residual of (11)      \
       vanish; stages see it through the mode's copy of the model), what one advance puts back on failure, the     \
       events' states and the complementarity problems' vectors */                                                  \
    ARRAY(double, mode_inv_R, m->n_ropes ? m->L : 0)                                                                \
    ARRAY(uint8_t, active_start, m->n_ropes ? m->L : 0)                                                             \
    ARRAY(double, impulse_start, m->n_ropes ? m->L : 0)                                                             \
    ARRAY(double, slip_reference_start, 3 * m->n_grips / 2)                                                       \
    ARRAY(uint8_t, mask, m->n_ropes ? m->L : 0)                                                                     \
    ARRAY(uint8_t, rope_flags, m->n_ropes ? 11 * m->n_ropes : 0)  /* (11, n_ropes) sets of ropes */                   \
    ARRAY(double, rope_values, m->n_ropes ? 10 * m->n_ropes : 0)  /* (10, n_ropes) per-rope values */                 \
    ARRAY(double, event_states, m->n_ropes ? 16 * 3 * m->K : 0)  /* (16, K, 3) states */                           \
    ARRAY(double, event_U_before, m->n_ropes && m->n_driven ? 3 * m->K : 0)  /* (K,3) the velocities an event     \
                                                           began with: their change gives the driven anchors'      \
                                                           impulse */                                               \
    ARRAY(double, event_ground_impulse, m->n_grips && m->n_driven ? 3 * m->K : 0)  /* (K,3) the ground's impulse  \
                                                           along its plane on each mass in an event's impact (the  \
                                                           friction's, the grips'): not the links' */              \
    ARRAY(double, link_values, m->n_ropes ? 6 * m->L : 0)        /* (6, L) per-link values */                       \
    ARRAY(double, E_full, m->n_ropes ? 3 * m->L : 0)             /* (L,3) every link's unit vector, slack or not */ \
    /* the ropes' tensions at an adaptive step's inner stages (its accepted attempt's): where a force that falls   \
       through zero and rises again within the step is looked for (ln_rope_step_events) */                        \
    ARRAY(double, stage_tensions, m->n_ropes ? s->n_stages_allocated * m->n_ropes : 0)  /* (stages, n_ropes) */    \
    SCALAR(double, stage_force_scale)                   /* the largest |T| of the mode's links at those stages */

/* The declarations of the fields, for the struct's body. */
#define LN_DECLARE_DATA_SCALAR(type, name) type name;
#define LN_DECLARE_DATA_ARRAY(type, name, count) type *name;
#define LN_DECLARE_DATA_OWNED(type, name, release) type *name;
#define LN_DECLARE_DATA_BORROWED(type, name) type *name;
#define LN_DECLARE_DATA_FIELDS                                                                                      \
    LN_DATA_FIELDS(LN_DECLARE_DATA_SCALAR, LN_DECLARE_DATA_SCALAR, LN_DECLARE_DATA_ARRAY, LN_DECLARE_DATA_OWNED,    \
                   LN_DECLARE_DATA_BORROWED)

#endif
