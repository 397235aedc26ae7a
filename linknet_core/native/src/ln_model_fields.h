/* The fields of the core's constant structs, each written once, as MuJoCo's mjxmacro.h lists mjModel's.
 *
 * From these lists the preprocessor declares linknet.h's ln_model, ln_method and ln_energy_terms and rigid.h's struct
 * ln_rigid_model, and model_fields.c the table of their fields (name, type, offset, number of entries) that the
 * library exports. The Python binding builds its ctypes mirrors from that table when it loads the library
 * (linknet_core/clib/library.py), and the native FMU writes the model's into its resource file from it
 * (fmu_src/native/build.py) and reads them back with these same lists (fmu_src/native/linknet_model.c). Adding a
 * field is one line here, plus the code that fills it.
 *
 * Each list takes four macros, one per kind of field:
 *   SCALAR(type, name)           type name;
 *   ARRAY(type, name, count)     const type *name;   count: how many entries it points to, an expression in the
 *                                struct's earlier fields through `s` (the struct) and `m` (the ln_model it belongs
 *                                to; for ln_model itself m is s). A NULL pointer has no entries, whatever count says.
 *   FIXED(type, name, n)         type name[n];
 *   OPAQUE(type, name)           const type *name;   an object of the process that built it (a factorisation's
 *                                analysis, ...): rebuilt by whoever loads the struct, never copied as data
 * where type (SCALAR, ARRAY, FIXED) is one of ln_int, int, double, uint8_t: LN_FIELD_CODE(type) is its code, the
 * character Python's struct module gives the same type ('q', 'i', 'd', 'B').
 */
#ifndef LINKNET_MODEL_FIELDS_H
#define LINKNET_MODEL_FIELDS_H

#define LN_FIELD_CODE(type) LN_FIELD_CODE_##type
#define LN_FIELD_CODE_ln_int 'q'
#define LN_FIELD_CODE_int 'i'
#define LN_FIELD_CODE_double 'd'
#define LN_FIELD_CODE_uint8_t 'B'
#define LN_FIELD_CODE_uint64_t 'Q'
#define LN_FIELD_CODE_char 'c'

#define LN_PIECE_COLUMNS 14     /* a piecewise-cubic motion's row: start, base, then c0..c3 of each axis */
#define LN_SINE_COLUMNS 12      /* a sine motion: origin, amplitude, angular frequency, phase (3 each) */

/* ln_model: the scene's topology, masses, lengths, force elements and the structure analysed once in Python. */
#define LN_MODEL_FIELDS(SCALAR, ARRAY, FIXED, OPAQUE)                                                               \
    SCALAR(ln_int, K)                                   /* masses */                                                \
    SCALAR(ln_int, L)                                   /* links */                                                 \
    ARRAY(ln_int, k1, s->L)                             /* the masses joined by link l (5), 0-based */              \
    ARRAY(ln_int, k2, s->L)                                                                                         \
    ARRAY(double, R, s->L)                              /* R_l (6) */                                               \
    ARRAY(double, inv_R, s->L)                          /* 1/R_l */                                                 \
    ARRAY(double, inv_m, s->K)                          /* 1/M_k; 0 on anchored masses */                           \
    SCALAR(ln_int, n_free)                                                                                          \
    ARRAY(ln_int, free_idx, s->n_free)                                                                              \
    SCALAR(ln_int, n_fixed)                                                                                         \
    ARRAY(ln_int, fixed_idx, s->n_fixed)                                                                            \
    ARRAY(uint8_t, is_fixed, s->K)                                                                                  \
    /* F_k of (9): the part fixed over a run, and the state-dependent force elements (stages/forces.c names the     \
       kinds and gives each its formula and the meaning of its parameters) */                                       \
    ARRAY(double, F_scene, 3 * s->K)                    /* (K,3) M_k g + constant forces; zero on anchors */        \
    SCALAR(ln_int, n_elements)                                                                                      \
    ARRAY(ln_int, element_kind, s->n_elements)          /* ln_force_kind of the kind's name */                      \
    ARRAY(ln_int, element_mass, 2 * s->n_elements)      /* (n_elements,2) the masses it acts on, -1 where unused */ \
    ARRAY(double, element_param, LN_FORCE_PARAMETERS * s->n_elements)  /* (n_elements, LN_FORCE_PARAMETERS) */      \
    SCALAR(int, velocity_dependent)                     /* an element depends on U: RATTLE's second kick implicit */\
    /* the tension system (25) */                                                                                   \
    SCALAR(int, solver)                                 /* enum ln_solver */                                        \
    SCALAR(ln_int, n_pairs)                             /* pairs of links coupled in A (diagonal pairs included) */ \
    ARRAY(ln_int, pair_first, s->n_pairs)                                                                           \
    ARRAY(ln_int, pair_second, s->n_pairs)                                                                          \
    ARRAY(double, pair_weight, s->n_pairs)              /* S(l,l')/M(l,l') of (21)-(22), 1/M of one end on the      \
                                                           diagonal (18) */                                         \
    ARRAY(ln_int, pair_mass, s->n_pairs)                /* the free mass the two links of each pair share */        \
    ARRAY(double, pair_sign, s->n_pairs)                /* S(l,l') of (21) of each pair; +1 on the diagonal */      \
    ARRAY(ln_int, chain_order, s->L)                    /* chains: links in path order */                           \
    ARRAY(double, chain_diag_weight, s->L)              /* chains, in path order */                                 \
    ARRAY(double, chain_off_weight, s->L)                                                                           \
    OPAQUE(struct ln_ldl_symbolic, ldl)                 /* LN_SOLVER_LDL (NULL for the others) */                   \
    SCALAR(double, pivot_tol)                           /* a pivot below pivot_tol times its diagonal entry: A is   \
                                                           singular */                                              \
    SCALAR(double, rank_tol)                            /* minimum-norm solves: pivots below rank_tol times the     \
                                                           largest are zero */                                      \
    SCALAR(ln_int, dense_min_norm_limit)                /* links; above it minimum-norm solves are iterative */     \
    /* planar scenes: the plane's orthonormal in-plane basis P (3x2, row-major), a point o, the unit normal n, the   \
       scene's size (scale of the in-plane test) and the round-off tolerance of that test */                        \
    SCALAR(int, planar)                                                                                             \
    FIXED(double, plane_P, 6)                                                                                       \
    FIXED(double, plane_o, 3)                                                                                       \
    FIXED(double, plane_n, 3)                                                                                       \
    SCALAR(double, plane_length)                                                                                    \
    SCALAR(double, plane_tol)                                                                                       \
    OPAQUE(struct ln_rigid_model, rigid)                /* free rigid bodies, or NULL */                            \
    /* driven anchors (drive.c): anchored masses (1/M = 0, in fixed_idx) whose motion P_a(t) is prescribed. Their   \
       rows of X and U hold P_a and V_a; in B of (26) a_k = accel_weight[k] F_k, which is F_k/M_k on a free mass    \
       and, with weight 1, the anchor's acceleration A_a on a driven anchor, whose row of the base force holds it.  \
       Scenes with driven anchors run in 3-D. */                                                                    \
    SCALAR(ln_int, n_driven)                                                                                        \
    ARRAY(ln_int, driven_idx, s->n_driven)              /* their masses */                                          \
    ARRAY(ln_int, motion_kind, s->n_driven)             /* enum ln_motion_kind (drive.c) */                         \
    ARRAY(ln_int, motion_pieces, s->n_driven ? s->n_driven + 1 : 0)  /* offsets of each piecewise-cubic motion's    \
                                                           rows in piece */                                         \
    ARRAY(double, piece, LN_PIECE_COLUMNS * (s->n_driven && s->motion_pieces ? s->motion_pieces[s->n_driven] : 0))  \
                                                        /* (rows, 14): start, base, then c0..c3 of each axis in     \
                                                           powers of tau - base */                                  \
    ARRAY(double, sine, LN_SINE_COLUMNS * s->n_driven)  /* (n_driven, 12): origin, amplitude, angular frequency,     \
                                                           phase (3 each) */                                        \
    ARRAY(double, accel_weight, s->K)                   /* 1/M_k; 1 on driven anchors (the same array as inv_m      \
                                                           without them) */                                         \
    /* the position projection's stopping rule (stages/projections.c): a residual within the round-off floor plus   \
       floor_safety times what the Newton step leaves by construction is at the floor the conditioning allows, but  \
       never above floor_cap times the convergence scale (linknet_core.dynamics.equations: FLOOR_SAFETY,            \
       FLOOR_CAP_OVER_TOL) */                                                                                       \
    SCALAR(double, floor_safety)                                                                                    \
    SCALAR(double, floor_cap)                                                                                       \
    /* a position projection's Gauss-Newton that would fail is retried once with its minimum-norm solves cutting   \
       at retry_rank_tol instead of rank_tol (linknet_core.structure.RETRY_SINGULAR_RCOND); 0: no retry */          \
    SCALAR(double, retry_rank_tol)                                                                                  \
    /* ropes (stages/ropes.c): links that only pull, each slack or taut (the mode, ln_data.link_active); their     \
       events' tolerances, filled from the numpy reference's single source (linknet_core.dynamics.unilateral:      \
       TOUCH_TOL, CROSS_TOL, FORCE_TOL, REST_HEIGHT, IMPULSE_ROUNDOFF; .complementarity: LCP_TOL, PIVOTS_PER_ROW, ENUMERATION_LIMIT;  \
       linknet_core.integrators.events: MAX_EVENTS_PER_STEP, GAP_NEWTON_ITERATIONS, SHORT_STEP). A rope's length scale is its   \
       R_l. No ropes: n_ropes = 0 and nothing of this is read */                                                   \
    SCALAR(ln_int, n_ropes)                                                                                         \
    ARRAY(ln_int, rope_link, s->n_ropes)                /* the link of each rope, in link order */                  \
    ARRAY(double, rope_restitution, s->n_ropes)         /* Newton's restitution of each rope's jerk */              \
    SCALAR(double, touch_tol)                                                                                       \
    SCALAR(double, cross_tol)                                                                                       \
    SCALAR(double, force_tol)                                                                                       \
    SCALAR(double, rest_height)                                                                                     \
    SCALAR(double, impulse_roundoff)                                                                                \
    SCALAR(double, lcp_tol)                                                                                         \
    SCALAR(ln_int, pivots_per_row)                                                                                  \
    SCALAR(ln_int, enumeration_limit)                                                                               \
    SCALAR(ln_int, max_events_per_step)                                                                             \
    SCALAR(ln_int, gap_newton_iterations)                                                                           \
    SCALAR(double, short_step)                          /* fixed-step methods: a part of a step shorter than this   \
                                                           fraction of dt is a Taylor step (events.SHORT_STEP) */   \
    SCALAR(double, scene_size)                          /* the scene's length scale, m (UnilateralDynamics.size) */ \
    SCALAR(double, gravity_norm)                        /* |g|, m/s^2: the velocity and rest speed scales */        \
    /* a ground (stages/ropes.c): the plane n . (X - p) >= 0 under every free mass, each contact a unilateral link    \
       from its mass to a virtual anchor placed straight above it (UnilateralDynamics' ModeDynamics): the model's   \
       last n_contacts masses before the grips' are the anchors (fixed, infinite mass), its last n_contacts links  \
       before the grips' the contacts (the last n_contacts of its ropes, of length scene_size and the ground's       \
       restitution), in the order of their masses. No ground: n_contacts = 0 and nothing of this is read */          \
    SCALAR(ln_int, n_contacts)                                                                                      \
    ARRAY(ln_int, contact_mass, s->n_contacts)          /* the free mass of each contact */                         \
    FIXED(double, ground_point, 3)                      /* p, m */                                                  \
    FIXED(double, ground_normal, 3)                     /* n, unit */                                               \
    /* Coulomb friction on the ground (mu > 0): two grip links per contact from its mass to two virtual anchors at   \
       rest beside it along the plane's tangents t_1, t_2 (ModeDynamics' grips), in the mode while the contact       \
       sticks (ln_data.contact_stuck): the model's last n_grips links and masses, after the contacts', grip i of     \
       contact c being link L - n_grips + 2 c + i and mass K - n_grips + 2 c + i. No friction: n_grips = 0 */       \
    SCALAR(double, friction)                            /* mu */                                                    \
    FIXED(double, ground_tangent, 6)                    /* t_1, t_2 (unilateral._tangents of n) */                 \
    SCALAR(ln_int, n_grips)                             /* 2 n_contacts with friction, else 0 */

/* ln_method: what an integrator is, the method as data. */
#define LN_METHOD_FIELDS(SCALAR, ARRAY, FIXED, OPAQUE)                                                              \
    SCALAR(int, kind)                                   /* enum ln_method_kind */                                   \
    SCALAR(double, dt)                                  /* fixed-step methods: the longest step */                  \
    SCALAR(ln_int, n_gammas)                            /* compositions: step fractions (RATTLE: one, 1.0) */       \
    ARRAY(double, gammas, s->n_gammas)                                                                              \
    SCALAR(ln_int, n_stages)                            /* Runge-Kutta: s */                                        \
    ARRAY(double, AB, (s->n_stages + 1) * s->n_stages)  /* ((s+1) x s) the tableau's A with the weights b as row s */\
    ARRAY(double, C, s->n_stages)                       /* the nodes c_i: stage i is at t + c_i h (driven anchors'  \
                                                           motion) */                                               \
    ARRAY(double, E1, s->n_stages + 1)                  /* error weights (E2 zero for a single estimate) */         \
    ARRAY(double, E2, s->n_stages + 1)                                                                              \
    SCALAR(int, error_norm)                             /* enum ln_error_norm */                                    \
    SCALAR(double, exponent)                            /* step-size controller exponent, -1/(order of the estimate \
                                                           + 1) */                                                  \
    SCALAR(double, safety)                                                                                          \
    SCALAR(double, min_factor)                                                                                      \
    SCALAR(double, max_factor)                                                                                      \
    SCALAR(double, real_stability)                      /* |R(z)| <= 1 for -real_stability <= z <= 0: the stability \
                                                           interval of the tableau on the negative real axis */     \
    SCALAR(double, stiff_safety)                        /* the fraction of it a sliding contact's step cap uses */  \
    SCALAR(double, straight_slip)                       /* the cap spares a slip turning by a smaller sine */       \
    SCALAR(double, rtol)                                                                                            \
    SCALAR(double, atol)                                                                                            \
    SCALAR(double, position_tol)                        /* relative tolerance of the position projection onto (11) */\
    SCALAR(ln_int, max_projection_iter)

/* struct ln_rigid_model (rigid.h): free rigid bodies, fixed for a run. */
#define LN_RIGID_MODEL_FIELDS(SCALAR, ARRAY, FIXED, OPAQUE)                                                         \
    SCALAR(ln_int, n_bodies)                            /* B */                                                     \
    ARRAY(ln_int, body_of, m->K)                        /* body of each mass; -1 for a mass of no body (an anchor   \
                                                           joined by no link, which holds only springs) */          \
    ARRAY(double, r, 3 * m->K)                          /* (K,3) body-frame position of each mass relative to its   \
                                                           body's centre of mass (zero off the bodies) */           \
    ARRAY(double, inertia, 3 * s->n_bodies)             /* (B,3) principal moments I_1, I_2, I_3 (a symmetric top's \
                                                           first two equal) */                                      \
    ARRAY(double, body_mass, s->n_bodies)                                                                           \
    ARRAY(ln_int, kind, s->n_bodies)                    /* enum ln_top */

/* ln_energy_terms (linknet.h): what a sample's energy needs beyond the model (diagnostics.c), as the numpy reference
   writes its terms: the masses, the weights M_k g, the constant forces and the springs (the force elements with a
   potential). */
#define LN_ENERGY_TERMS_FIELDS(SCALAR, ARRAY, FIXED, OPAQUE)                                                        \
    ARRAY(double, mass, m->K)                           /* (K) M_k (anchors' entries unused) */                     \
    ARRAY(double, weight, 3 * m->K)                     /* (K,3) M_k g, zero rows on anchors */                     \
    ARRAY(double, force, 3 * m->K)                      /* (K,3) the scene's constant forces (anchors' rows unused) */\
    SCALAR(ln_int, n_springs)                                                                                       \
    ARRAY(ln_int, spring_mass, 2 * s->n_springs)        /* (n_springs,2) the masses a, b of each */                 \
    ARRAY(double, spring_param, 2 * s->n_springs)       /* (n_springs,2) k, d0 of each */

/* The declarations of the fields, for a struct's body. */
#define LN_DECLARE_SCALAR(type, name) type name;
#define LN_DECLARE_ARRAY(type, name, count) const type *name;
#define LN_DECLARE_FIXED(type, name, n) type name[n];
#define LN_DECLARE_OPAQUE(type, name) const type *name;
#define LN_DECLARE_FIELDS(LIST) LIST(LN_DECLARE_SCALAR, LN_DECLARE_ARRAY, LN_DECLARE_FIXED, LN_DECLARE_OPAQUE)

#endif
