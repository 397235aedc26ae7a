/* linknet native core: the immutable model, the mutable data and the stage functions.
 *
 * Equation numbers (n) are those of the seed note "Mechanics of a network of rigid links with point
 * masses at the vertices". K point masses M_k at X_k with velocities U_k and external forces F_k; L rigid
 * links l joining k1(l), k2(l) with lengths R_l. The tensions T solve A T = B (25)-(26) with
 * A = C M^-1 C^T, row l of C being +E_l at k1(l) and -E_l at k2(l), E_l = (X_k2 - X_k1) / R_l (8).
 *
 * As MuJoCo keeps mjModel apart from mjData, the model (topology, masses, lengths, force elements and
 * the structure analysed once in Python) never changes during a run and is only read; the data holds
 * t, X, U, the integrator's internals and every scratch array. Stage functions take (const model*, data*).
 *
 * Vectors have DIM components: planar scenes run in their plane's coordinates (DIM = 2), everything
 * else in 3-D. The DIM-generic stage files are compiled twice, by dim2.c and dim3.c; FN(name) gives each
 * copy its own symbol (name_2d, name_3d). The state in ln_data is always (K,3).
 *
 * No dependency beyond libc (the elementary functions are ln_math.c's); no allocation inside a step (ln_data_new allocates everything,
 * except the minimum-norm workspace, allocated at its first use).
 */
#ifndef LINKNET_H
#define LINKNET_H

#include <stddef.h>
#include <stdint.h>

#include "ln_data_fields.h"
#include "ln_model_fields.h"

/* No fused multiply-add: every a*b+c of the core is rounded twice, as the platforms without FMA do, so that one
   source gives one arithmetic wherever it is compiled. Every build passes -ffp-contract=off as well; clang and MSVC
   also obey the pragma (clang contracts by default), GCC's ISO C modes (-std=c99) do not contract (its GNU modes
   would: the FMU's CMakeLists passes -ffp-contract=off; a pragma here would follow definitions in stages.h). */
#if defined(__clang__)
#pragma STDC FP_CONTRACT OFF
#elif defined(_MSC_VER)
#pragma fp_contract(off)
#endif

#ifdef __cplusplus
extern "C" {
#endif

typedef int64_t ln_int;

/* The library's interface (what ctypes, the FMU glue and tests call) is exported; everything else, the
   DIM-generic stages among it, stays inside the library (compiled with -fvisibility=hidden), so that the
   calls between stages are direct and can be inlined. */
#ifndef LN_API  /* an embedder (the native FMU) may define it empty */
#if defined(__GNUC__) || defined(__clang__)
#define LN_API __attribute__((visibility("default")))
#else
#define LN_API
#endif
#endif

/* Status of a stage or of a whole advance. Keep in step with linknet_core/clib/library.py (STATUS). */
enum ln_status {
    LN_OK = 0,
    LN_PROJECTION_FAILED = 1,   /* the position projection onto (11) did not converge */
    LN_SINGULAR = 2,            /* a vanishing pivot where no minimum-norm path was possible */
    LN_NON_FINITE = 3,          /* NaN or infinity in the state or the forces */
    LN_STEP_UNDERFLOW = 4,      /* adaptive step below 16 ulps of t */
    LN_TOO_MANY_STEPS = 5,      /* more accepted steps than max_steps in one advance */
    LN_LEFT_PLANE = 6,          /* internal: the state or the input left the plane (the advance goes on in 3-D) */
    LN_IMPLICIT_KICK_FAILED = 7,/* RATTLE's implicit velocity half step (drag, dampers) did not converge */
    LN_BAD_ARGUMENT = 8,        /* a target time not after t, a negative count, ... */
    LN_NO_MEMORY = 9,
    LN_DRIVE_FAILED = 10,       /* the driven anchors' motion callback failed (or returned non-finite values) */
    LN_EVENT_CHATTER = 11,      /* ropes: more events than max_events_per_step in consecutive steps */
    LN_NO_MODE = 12,            /* ropes: the complementarity problem of the touching ropes has no solution, or it
                                   cycled and is too large to enumerate */
    LN_NOT_LINEARIZABLE = 13    /* the outputs' linearization asked of a model with ropes: it is the rods' (25)-(26),
                                   which holds within one mode only */
};

/* What an event of a rope or the ground is (ln_data's event log: a rope's events name its link, a contact's its
   mass). Keep in step with linknet_core/clib/library.py. */
enum ln_event_kind {
    LN_EVENT_TAUT = 0, LN_EVENT_SLACK = 1, LN_EVENT_CONTACT = 2, LN_EVENT_RELEASE = 3,
    LN_EVENT_STICK = 4, LN_EVENT_SLIP = 5  /* friction: a sliding mass stopped and sticks; a stuck one slides */
};

/* How A of (25) is factored, chosen once per scene from its structure. */
enum ln_solver {
    LN_SOLVER_NONE = 0,     /* no links */
    LN_SOLVER_CHAIN = 1,    /* tridiagonal in path order: two sweeps per right-hand side */
    LN_SOLVER_LDL = 2,      /* sparse LDL^T on the pattern analysed once (trees: no fill) */
    LN_SOLVER_MIN_NORM = 3  /* redundant links (self-stresses): minimum-norm tensions */
};

/* What an integrator is: the method as data. */
enum ln_method_kind {
    LN_COMPOSITION = 0,     /* RATTLE and its symmetric compositions: the step fractions gammas */
    LN_RUNGE_KUTTA = 1,     /* explicit embedded Runge-Kutta on the index-1 form, projected: the tableau */
    LN_STATIC = 2           /* 0 degrees of freedom: nothing moves, an advance moves t only */
};

enum ln_error_norm { LN_RMS_ERROR = 0, LN_HAIRER_ERROR = 1 };

#define LN_FORCE_PARAMETERS 4       /* parameters per force element */

struct ln_rigid_model;      /* engine_rigid.c: free rigid bodies (rigid.h) */
struct ln_rigid_data;
struct ln_minnorm_work;     /* stages/minnorm.c: minimum-norm solves (minnorm.h) */

struct ln_ldl_symbolic;     /* engine_ldl.c: sparse LDL^T of A, analysed once (ldl.h) */
struct ln_ldl_numeric;

/* The model: its fields are listed in ln_model_fields.h (LN_MODEL_FIELDS), with what each means. */
typedef struct ln_model {
    LN_DECLARE_FIELDS(LN_MODEL_FIELDS)
} ln_model;

/* A method: its fields are listed in ln_model_fields.h (LN_METHOD_FIELDS). */
typedef struct ln_method {
    LN_DECLARE_FIELDS(LN_METHOD_FIELDS)
} ln_method;

/* What input-driven anchors follow when a data's drive_callback is set: P, V, A of each input-driven anchor in turn
   at t (9 values per anchor) into PVA; 0 on success. */
typedef int ln_drive_motion(void *user, double t, double *PVA);

/* The data: the state t, X, U, the integrator's internals and every scratch array. Its fields are listed in
   ln_data_fields.h (LN_DATA_FIELDS), with what each means and how it lives. */
typedef struct ln_data {
    LN_DECLARE_DATA_FIELDS
} ln_data;

/* ---- data.c: allocation and the whole-interval advance ------------------------------------------ */
LN_API ln_data *ln_data_new(const ln_model *m, ln_int n_stages);  /* NULL: out of memory */
/* stages/rattle.c: the n_stages a fixed-step method of meth needs beyond its own on m (the rows its screen of the
   ropes' forces inside a step keeps at its RATTLE stages' midpoints; 0 for the others) */
LN_API ln_int ln_midpoint_rows(const ln_model *m, const ln_method *meth);
LN_API void ln_data_free(ln_data *d);
/* Put d back to what ln_data_new(m, ...) made (the state, internals, counters, diagnostics, the driven anchors'
   hold and every scratch array), keeping its allocations and its scene time origin drive_t0: a run on a reset
   data is the run on a new one. Not for free rigid bodies (their ln_rigid_data is not reset). */
LN_API void ln_data_reset(const ln_model *m, ln_data *d);

/* Advance d from d->t to t_target with d->F_input held (zero-order hold), all or nothing: on any status
   but LN_OK the state and internals are those before the call, and the diagnostics say why. */
LN_API int ln_advance(const ln_model *m, const ln_method *meth, ln_data *d, double t_target, ln_int max_steps);

/* stages/ropes.c, for scenes with ropes: the tensions and accelerations at X, U (K,3) with d->F_input held, in the
   mode the state is in (the acceleration complementarity problem on the ropes at their length and not separating:
   a pure function of the state, as the numpy reference's UnilateralDynamics.resolve), slack ropes' T exactly 0.
   ln_evaluate calls it for a model with ropes. The integrator's mode is not changed. */
int ln_rope_evaluate(const ln_model *m, ln_data *d, const double *X, const double *U);
/* A jump of the driven anchors' motion at d->t to P, V (n_driven,3) in a scene with ropes, as an event: the ropes it
   stretched put back with the touching ones, the impact law taking the jerk (each rope's restitution, the rods'
   rates (12) to zero), the mode chosen from the state after it, taut events for every rope it jerked; d->impulse
   what the links gave each driven anchor (EventHandling.anchor_jump). ln_drive_jump calls it. */
int ln_rope_anchor_jump(const ln_model *m, const ln_method *meth, ln_data *d, const double *P, const double *V);
/* The initial state (X, U) of a scene with ropes or a ground made consistent in place, as UnilateralDynamics.
   initial_state makes it: where project, the positions projected onto the rods and the ropes longer than their length
   (the closest in the mass metric); the contacts' anchors placed; then an inelastic impact on the ropes at their
   length and the masses on the ground (their approach velocities removed, the rods' rates (12) to zero), frictionless.
   d's mode is left to the first advance to choose. LN_OK, or the status of the projection or impact that failed.
   The library's native backend (linknet_core.native.integrator.core_initial_state) and the native FMU start from it. */
LN_API int ln_rope_initial_state(const ln_model *m, const ln_method *meth, ln_data *d, double *X, double *U,
                                 int project);
/* The log of events kept since the last drain is taken: the count is returned and the log emptied (the events are
   d->event_t, event_kind, event_link, event_impulse [0, count) until the next advance). */
LN_API ln_int ln_rope_events_drained(ln_data *d);

/* The driven anchors brought to their motion at d->t where it jumped, as every advance starts (drive.c's jump: the
   rods' projection, or with ropes the rope event), and nothing else: the outputs a run will start from. Not all or
   nothing: the caller keeps what it needs to put back (the state, the mode, the log). */
LN_API int ln_jump_anchors(const ln_model *m, const ln_method *meth, ln_data *d);

/* What a sample's energy needs beyond the model (diagnostics.c): its fields are listed in ln_model_fields.h
   (LN_ENERGY_TERMS_FIELDS). */
typedef struct ln_energy_terms {
    LN_DECLARE_FIELDS(LN_ENERGY_TERMS_FIELDS)
} ln_energy_terms;

/* Samples of a run at the output times times[0..n) with d->F_input held throughout: advance to each (ln_advance,
   all or nothing; sample 0 is taken at the current state unless advance_first) and evaluate the outputs there
   (ln_evaluate), writing X, U (K,3) and T (L) of sample i into X_out, U_out (n,K,3) and T_out (n,L), unless
   T_peak_out is NULL the located tension peaks of the interval that ended at sample i (ln_tension_peaks: each
   link's largest |T_l|, signed; at a sample taken without an advance its T) and their times into T_peak_out and
   T_peak_time_out (n,L), and, unless diagnostics_out is NULL, the sample's diagnostics (ln_sample_diagnostics) into column i of diagnostics_out, four
   rows (energy, residuals of (11) and (12), kinetic energy) diagnostics_stride apart: the layout the run's result
   hands out, one row per quantity.
   What simulate's output loop does per sample, in one call. Stops at the first status but LN_OK: *written samples
   were written; the state is then that of the last sample, or, when the evaluation failed, the one it failed at
   (d->t tells which). */
LN_API int ln_sample(const ln_model *m, const ln_method *meth, ln_data *d, const double *times, ln_int n,
                     int advance_first, ln_int max_steps, double *X_out, double *U_out, double *T_out,
                     double *T_peak_out, double *T_peak_time_out, const ln_energy_terms *energy,
                     double *diagnostics_out, ln_int diagnostics_stride, ln_int *written);

/* diagnostics.c: a sample's energy (kinetic plus the potential of gravity, constant forces and springs), the
   largest relative violation of (11), the largest violation of (12) (m/s) and the kinetic energy, in out[0..4),
   at X, U (K,3): the numpy reference's values (linknet_core.dynamics), bit for bit. */
LN_API void ln_sample_diagnostics(const ln_model *m, const ln_energy_terms *e, const double *X, const double *U,
                                  double out[4]);

/* The tensions T of (25)-(26) and accelerations (9) at X, U (K,3) with d->F_input held (the reported outputs:
   direct feedthrough of F), and the force the links exert on each anchor, sum_l T_l E_l (delta(k,k1(l)) -
   delta(k,k2(l))) of (9) at the anchored k. Minimum-norm where A is singular. Results in d->T, d->acc,
   d->reaction. */
LN_API int ln_evaluate(const ln_model *m, ln_data *d, const double *X, const double *U);

/* n evaluations of the right-hand side at the same state in one call, in dim = 3 or (planar scenes, X and U
   in the plane's coordinates, (K,2)) dim = 2 components: the right-hand side the integrators call, timed
   without a call from Python for each (benchmarks). Results in d->acc, d->T (in dim components). */
LN_API int ln_evaluate_repeated(const ln_model *m, ln_data *d, int dim, const double *X, const double *U, ln_int n);

/* controller.c: the step-size controller of the embedded Runge-Kutta pairs. The step taken next from t (h_next
   cut to land on t_target with no sliver of a last step; -1 on underflow within 16 ulps of t); the step
   after one of size h with error norm err (grown when accepted, shrunk when rejected or not finite); Hairer-Wanner's
   starting step from the norms d0 = |y|, d1 = |f(y)|, d2 = |f(y + h0 f) - f(y)| / h0 of the state. */
LN_API double ln_controlled_step(double h_next, double t, double t_target);
LN_API double ln_next_step_size(const ln_method *meth, double h, double h_next, double err);
LN_API double ln_trial_step(double d0, double d1, double span);
LN_API double ln_starting_step(const ln_method *meth, double h0, double d1, double d2, double span);

/* Gravity, constant forces and the held input d->F_input: the part of F_k of (9) fixed over an interval, zero
   on anchors. 0 when it is not finite. */
LN_API int ln_base_forces(const ln_model *m, const ln_data *d, double *F_base);

/* drive.c: P, V, A (n_driven,3 each) of every driven anchor at t. LN_OK, or LN_DRIVE_FAILED when the callback
   failed or gave non-finite values. */
LN_API int ln_drive_at(const ln_model *m, ln_data *d, double t, double *P, double *V, double *A);

/* stages/projections.c: a state (K,3) onto the manifolds. With positions, X onto (11) along M^-1 C(X)^T mu from X
   itself (the closest point in the mass metric; relative tolerance tol, at most max_iter iterations); then U onto
   (12) at the new X, U -= M^-1 C^T mu with A(X) mu = C U. mu: NULL, or (L) where the velocity projection's
   multipliers are kept (the links give an anchored mass k the impulse -(C^T mu)_k). LN_OK, or the status of the
   projection or factorisation that failed (d->fail_* then say where). Scratch: d->E0, d->phi and the projections'. */
LN_API int ln_project_state(const ln_model *m, ln_data *d, double *X, double *U, int positions, double tol,
                            ln_int max_iter, double *mu);

/* model_weights.c: what of the model follows from the masses M (K; anchors' entries unused), lengths R (L), gravity
   (3) and the scene's constant forces (K,3), written into weights (ln_model_weights_size(m) doubles, kept by the
   caller as long as m) and pointed at by m: R itself, inv_m, accel_weight, F_scene, inv_R, pair_weight and, for
   LN_SOLVER_CHAIN, chain_diag_weight and chain_off_weight. Reads the structure already in m: K, L, is_fixed, the
   pairs (pair_first, pair_second, pair_mass, pair_sign), the solver and chain_order, the driven anchors. LN_OK, or
   LN_NO_MEMORY. */
LN_API ln_int ln_model_weights_size(const ln_model *m);
LN_API int ln_model_weights(ln_model *m, const double *mass, const double *R, const double *gravity,
                            const double *force, double *weights);

/* Equal steps no longer than dt that land on the target: how many (a whole number up to round-off is that
   number, not one more); ln_max_step_count + 1 where there would be more than ln_max_step_count (2^53, the most
   one advance takes: ln_advance lowers a larger max_steps to it) or span / dt is not a number. */
LN_API extern const ln_int ln_max_step_count;
LN_API ln_int ln_fixed_step_count(double span, double dt);
/* Whether a fixed-step advance from t to t_target takes more than max_steps steps of dt (1), and then why, in words
   naming the span, dt, the count and the limit, into out (n bytes): the library's SolverError and the native FMU's
   message. 0, out untouched, where the count is within the limit. */
LN_API int ln_step_count_problem(double t, double t_target, double dt, ln_int max_steps, char *out, size_t n);

/* model_fields.c: the fields of the structs ln_model_fields.h and ln_data_fields.h list, as the Python binding builds
   its mirrors from them and the native FMU's build writes the constant structs as data. `which` is an enum ln_struct.
   ln_data's SCALAR and KEPT fields are SCALAR here, its OWNED and BORROWED ones OPAQUE. */
enum ln_struct {
    LN_MODEL_STRUCT = 0, LN_METHOD_STRUCT = 1, LN_RIGID_MODEL_STRUCT = 2, LN_DATA_STRUCT = 3, LN_ENERGY_TERMS_STRUCT = 4
};
enum ln_field_kind { LN_FIELD_SCALAR = 0, LN_FIELD_ARRAY = 1, LN_FIELD_FIXED = 2, LN_FIELD_OPAQUE = 3 };
/* Fields of the struct (-1: no such struct) and its size. */
LN_API ln_int ln_struct_fields(int which);
LN_API size_t ln_struct_size(int which);
/* Field i in list order: its name (NULL past the last field), and into the others (any may be NULL) its kind
   (enum ln_field_kind), type code (LN_FIELD_CODE: 'q', 'i', 'd', 'B'; 0 for OPAQUE), entries of a FIXED field,
   offset in the struct and size of one entry. */
LN_API const char *ln_struct_field(int which, ln_int i, int *kind, char *code, ln_int *fixed, size_t *offset,
                                   size_t *size);
/* The entries of field i of the struct at s (which belongs to the model m; for ln_model, m is s): 1 for a scalar,
   n for FIXED, the list's count for an ARRAY (0 where its pointer is NULL), 0 for OPAQUE; -1 for no such field. */
LN_API ln_int ln_struct_field_count(int which, ln_int i, const void *s, const ln_model *m);

/* The code of a force element kind named as in linknet_core.scene.description.FORCE_KINDS (stages/forces.c), or -1;
   the name of a code, or NULL past the last kind (the binding checks the kinds against FORCE_KINDS with it). */
LN_API ln_int ln_force_kind(const char *name);
LN_API const char *ln_force_kind_name(ln_int code);

/* ---- error_estimate.c: a run's global error from a companion run ---------------------------------- */

/* The companion run's settings for a run of a method (adaptive or of fixed step dt and order p) and the factor
   that turns the largest position gap between the two runs (ln_position_gap) into the run's error estimate:
   a fixed step is compared with half the step (Richardson: factor 2^p / (2^p - 1)), an error-controlled method
   with a tenth of its tolerances (factor 1, rtol no lower than ln_rtol_min). */
LN_API double ln_companion_settings(int adaptive, int order, double dt, double rtol, double atol,
                                    double *dt_companion, double *rtol_companion, double *atol_companion);
LN_API extern const double ln_rtol_min;

/* Advance the companion run dc to t_target in two halves (a fixed-step companion at its half step: twice the run's
   steps over every interval, however short; an error-controlled one twice as many steps where the communication
   points set the run's). LN_OK or ln_advance's status. */
LN_API int ln_companion_advance(const ln_model *m, const ln_method *companion, ln_data *dc, double t_target,
                                ln_int max_steps);

/* The warning of a run whose estimated error exceeds its goal from time t on, into out (n bytes); largest: the
   run's largest estimate, named where above estimate (0: none). The library's and the native FMU's one text. */
LN_API void ln_accuracy_text(const char *name, double t, double estimate, double goal, double largest, char *out,
                             size_t n);

/* The note of a run whose companion failed (why: where and how) where the run itself went through, into out. */
LN_API void ln_estimate_failure_text(const char *name, const char *why, char *out, size_t n);

/* The largest distance |Xa_k - Xb_k| over K masses (K,3), m; NaN if a coordinate is not finite. */
LN_API double ln_position_gap(ln_int K, const double *Xa, const double *Xb);
/* ln_position_gap of n pairs of states (n, K, 3), one gap per pair, into out (n): a run's estimate at every sample. */
LN_API void ln_position_gaps(ln_int n, ln_int K, const double *Xa, const double *Xb, double *out);

/* The position error (m) a run is held to: 100 times max(rtol times the scene's size, atol); a
   fixed-step run (adaptive 0) is held to that of ln_default_rtol. */
LN_API double ln_error_goal(int adaptive, double rtol, double atol, double size);
LN_API extern const double ln_default_rtol;

/* A scene's size: the largest extent of the positions X (K,3) along an axis, m (1 if they all coincide). */
LN_API double ln_scene_size(ln_int K, const double *X);

/* ---- explain.c: a failed advance in words (every path's one text) ---------------------------------- */

/* What a status is called ("projection failed", ...). */
LN_API const char *ln_status_name(int status);

/* The failure of an advance of d from t towards t_target with status, in words, into out (n bytes): what
   happened, where and what may help, from the diagnostics the failure left in d (d->T: the tensions at the start
   of a composition's step that failed). link_label names the link d->fail_link (NULL: "a link"); max_steps is
   the advance's limit. */
LN_API void ln_explain(const ln_model *m, const ln_method *meth, const ln_data *d, int status, double t,
                       double t_target, ln_int max_steps, const char *link_label, char *out, size_t n);

/* Why a position projection onto (11) failed, and what may help: beyond the stability limit of explicit steps
   (h omega > ln_stability_limit, with the margin ln_reads_low of the estimate, h = stage_fraction dt), stalled
   at its conditioning floor (reached within ln_near_floor times floor), or outside Newton's region of convergence.
   where: what the iteration reached and at which link; reached: its relative residual; before: the largest
   relative violation before projection; floor: the relative floor its last Newton step allowed (0: no Newton
   step); dt, stage_fraction (max |gamma_i|), omega: of a fixed-step method (0 for the others). */
LN_API void ln_projection_failure(const char *where, double reached, double before, double floor, double dt,
                                  double stage_fraction, double omega, char *out, size_t n);
LN_API extern const double ln_near_floor, ln_stability_limit, ln_reads_low;

/* The fastest oscillation (rad/s) of a free mass between its links at tensions T (L): omega_k^2 = sum over its
   links of |T_l| / (M_k R_l) (a bead on a string; the diagonal of M^-1 times the links' geometric stiffness);
   anchors (1/M = 0) do not oscillate. 0 when there is none or it is not finite. */
LN_API double ln_fastest_oscillation(const ln_model *m, const double *T);


#ifdef __cplusplus
}
#endif
#endif
