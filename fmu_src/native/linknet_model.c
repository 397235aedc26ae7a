/* One linknet scene as the model of fmu_model.h: the native core (linknet.h) on a scene's data, read from the FMU's
 * resource file when the model is made (lnfmu_scene.h; written by fmu_src/native/build.py).
 *
 * At the scene's default parameters the ln_model, ln_method and initial state are the scene data's, which are
 * those linknet_core's Simulator builds, so the FMU repeats the library's arithmetic bit for bit. A changed
 * mass, length or gravity (before the end of initialization) rebuilds what depends on it with the library's own
 * functions: 1/M, the base forces M g + F, the weights of A (25) and B (26) (ln_model_weights), the initial
 * state (lengths checked, positions projected if the scene opts in, velocities projected onto (12):
 * ln_project_state; zero for a static scene) and, for free rigid bodies, their layout and initial body states
 * (ln_rigid_layout).
 *
 * The error estimate (output error_estimate, Boolean parameter estimate_error): a companion run of the same scene,
 * a second ln_data advanced by a second ln_method after the run's own advance in every doStep, to the same
 * communication points with the same inputs, and never re-synchronised with the run (that would measure only the
 * local error). Its settings, the factor that turns the gap between the two runs into the estimate and the goal
 * the estimate is held to are the core's rule (error_estimate.c: ln_companion_settings, ln_position_gap,
 * ln_error_goal, ln_scene_size), the library's Simulator follows the same one: this file only calls it.
 *
 * Everything an instance changes lives in its fmu_model: instances are independent.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_model.h"
#include "interface_jacobian.h"
#include "ldl.h"
#include "linknet.h"
#include "ln_math.h"
#include "lnfmu_scene.h"
#include "rigid.h"
#include "tension_peaks.h"


/* as linknet_core.structure.bodies.freeze_initial_state and Simulator's initial projection */
#define RESHAPE_TOL 1e-13   /* initial link lengths off by more than this are projected before freezing a body */
#define PROJECTION_TOL 1e-14
#define PROJECTION_ITERATIONS 200

struct fmu_model {
    const lnfmu_scene *s;       /* read from the resource (lnfmu_scene_load), owned */
    fmu_model_info info;
    double start_time;
    double *value;              /* (n_real) inputs and parameters as set (outputs are read from the data) */
    ln_int integrator;          /* as set */
    double *applied;            /* (n_real) the parameter values the current model was built with */
    ln_int applied_integrator;
    int dirty;                  /* a parameter was set since the model was built */
    int estimate;               /* the Boolean parameter estimate_error as set */
    int applied_estimate;       /* the one the current run started with: the companion runs */
    int outputs_stale;          /* T and Freact not evaluated at the current state and inputs */
    int interface_stale;        /* the interface linearization not prepared at the current state and inputs */

    ln_model model;
    ln_method method;
    struct ln_ldl_symbolic *ldl;        /* the pattern of A does not change with the parameters: analysed once */
    struct ln_rigid_model rigid;        /* the bodies of a changed scene */
    ln_data *d;
    ln_int n_bodies;

    /* the error estimate: the companion's method (ln_companion_settings of the run's) and data, the factor that
       turns the largest position gap into the estimate, the run's goal (m), the estimate at the current time (0 at
       the start, +inf once the companion failed) and whether it was beyond the goal after the last step (the note
       is given once per crossing) */
    ln_method method_c;
    ln_data *dc;
    double factor, goal, error;
    int over_goal;

    /* the outputs T_peak and T_peak_time: the last step's located tension peaks, then their times ((2L), the core's
       ln_tension_peaks, taken when the step ends: a step that fails later overwrites the data's), once a step was
       taken since the run (re)started (stepped; before it the outputs are T and t) */
    double *peak;
    int stepped;

    /* ropes: the events of the last successful step, in the run's data's log (ln_rope_events_drained: they stay there
       until the next advance), and how many more it did not keep; the glue logs them (fmu_model_event) */
    ln_int events_logged, events_lost;

    /* a model built from changed parameters points into these */
    double *R, *weights;                /* (L), (ln_model_weights_size) */
    double *r, *inertia, *body_mass;
    ln_int *top;
    double *mass_full, *gravity;        /* (K), (3) the parameters being applied */
    double *X_init, *U_init, *Y_init;   /* the current model's initial state */
    double *Xo, *Uo, *Ys;               /* scratch: the state handed to ln_evaluate, body states */

    /* position jumps of the input-driven anchors (see "position jumps" below), per driven anchor: whether a P of it
       was set since the last step, and the first V or A set (value reference; -1: none); per driven anchor and
       axis: its P and Jreact value references (n_real: none), and the jump the step begins with (P, where the held
       motion had the anchor, whether the coordinate's jump counts and whether it is long); what was said once */
    unsigned char *p_set;
    long *va_vr;
    unsigned *p_vr, *jreact_vr;
    double *jump_P, *jump_X;
    unsigned char *jump_counted, *jump_long;
    int said_short_jump, said_set_without_p;

    /* directional derivatives (fmi2GetDirectionalDerivative): the core's linearization workspace, made at the first
       call and prepared once per state and inputs; the seed on F (K,3) and on the driven anchors' P, V, A
       (n_driven,3), and the derivatives of T (L) and Freact (n_fixed,3) along it */
    ln_interface *interface;
    double *seed_F, *seed_P, *seed_V, *seed_A, *dT, *dFreact;
};

#if defined __GNUC__
static int fail(char *msg, int result, const char *format, ...) __attribute__((format(printf, 3, 4)));
#endif

static int fail(char *msg, int result, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    vsnprintf(msg, FMU_MESSAGE, format, args);
    va_end(args);
    return result;
}

static const char *mass_name(const lnfmu_scene *s, ln_int k) { return s->mass_names[k]; }

/* The scene's own masses: the first of the model's, before a ground's virtual anchors, whose rows the core fills from
   their masses' and which are no part of the error estimate. */
static ln_int scene_masses(const lnfmu_scene *s) { return s->own_K; }

static void link_label(const lnfmu_scene *s, ln_int l, char *out, size_t n)
{
    const ln_int a = s->model->k1[l], b = s->model->k2[l];
    snprintf(out, n, "link %lld (%s-%s)", (long long)(l + 1), mass_name(s, a), mass_name(s, b));
}

static const lnfmu_variable *variable(const lnfmu_scene *s, unsigned vr) { return &s->variables[vr]; }

/* ---- position jumps of the input-driven anchors ---------------------------------------------------- */

/* Inputs set at t whose P is not where the held motion had the anchor at t make a position jump there, and so does a
   V or A set without P (the held motion restarts from the P last set). The core takes it as a relocation
   (drive.c ln_drive_jump): the anchor is put at P, the free masses are projected onto the link lengths (11) in the
   mass metric and their velocities onto (12), and the impulse of that velocity projection is reported (in Jreact,
   with the rope and ground events' of the step: ln_data.impulse; the projection's alone: jump_impulse), none
   for the displacement itself, which made in no time would take an unbounded impulse. The FMU says so, naming the
   inputs, in the pythonfmu FMU's words and by its rules (fmu_src/linknet_fmu/anchor_jumps.py): a coordinate's jump
   counts beyond JUMP_ROUND_OFF (|P| + the shortest link at the anchor); a jump of P longer than JUMP_LOGGED_ALWAYS of
   that link is logged every time, shorter ones once per instance; a V or A set without P once per instance. */
#define JUMP_ROUND_OFF 1e-12
#define JUMP_LOGGED_ALWAYS 1e-3
#define JUMP_MAX_LISTED 6
#define JUMP_RELOCATION                                                                                           \
    "A jump of position is no motion the links can follow (made in no time it would take an unbounded impulse), " \
    "so it was taken as a relocation: the anchor was put there, the free masses were moved to the nearest "      \
    "positions (in the mass metric) that keep the link lengths, and their velocities were projected onto the "   \
    "links relative to the anchor's velocity; the impulse of that projection is in Jreact (with those of the "   \
    "rope and ground events later in the step), none is counted for the displacement; the projection's: "
#define JUMP_RULE                                                                                                 \
    "a driven anchor's position input must continue its held motion P + V tau + A tau^2/2: a jump is taken by "  \
    "moving the free masses onto the link lengths at once, which fails where the links cannot follow it; move "  \
    "the anchor there over several steps (set P, V and A together, or give V and A as P's input derivatives)"

#if defined __GNUC__
static void append(char *out, size_t n, const char *format, ...) __attribute__((format(printf, 3, 4)));
#endif

/* printf onto the end of the text in out (n bytes), cut at its end */
static void append(char *out, size_t n, const char *format, ...)
{
    const size_t used = strlen(out);
    if (used + 1 >= n) return;
    va_list args;
    va_start(args, format);
    vsnprintf(out + used, n - used, format, args);
    va_end(args);
}

static void clear_anchor_marks(fmu_model *m)
{
    for (ln_int a = 0; a < m->s->model->n_driven; a++) {
        m->p_set[a] = 0;
        m->va_vr[a] = -1;
    }
}

/* The shortest link at mass k (INFINITY where it has none), at the lengths in force. */
static double shortest_link_at(const fmu_model *m, ln_int k)
{
    double shortest = INFINITY;
    for (ln_int l = 0; l < m->model.L; l++)
        if ((m->model.k1[l] == k || m->model.k2[l] == k) && m->model.R[l] < shortest) shortest = m->model.R[l];
    return shortest;
}

/* The position jump the step from the present state begins with (inputs set at this time): 1 when a coordinate's
   jump counts, its P, where the held motion had the anchor and which coordinates count and are long kept. */
static int position_jump(fmu_model *m)
{
    const ln_model *model = &m->model;
    const ln_data *d = m->d;
    if (model->n_driven == 0 || d->drive_hold_t != d->t) return 0;  /* the hold goes on: no new inputs */
    int any = 0;
    for (ln_int a = 0; a < model->n_driven; a++) {
        const ln_int k = model->driven_idx[a];
        double shortest = NAN;
        for (int e = 0; e < 3; e++) {
            const ln_int i = 3 * a + e;
            m->jump_counted[i] = m->jump_long[i] = 0;
            if (m->p_vr[i] == (unsigned)m->s->n_real) continue;  /* an anchor with a scene motion */
            const double P = d->drive_P[i], X = d->X[3 * k + e], jump = fabs(P - X);
            m->jump_P[i] = P;
            m->jump_X[i] = X;
            if (!(jump > 0.0)) continue;
            if (isnan(shortest)) shortest = shortest_link_at(m, k);
            m->jump_counted[i] = jump > JUMP_ROUND_OFF * (fabs(P) + shortest);
            m->jump_long[i] = m->jump_counted[i] && jump > JUMP_LOGGED_ALWAYS * shortest;
            any |= m->jump_counted[i];
        }
    }
    return any;
}

/* Whether the coordinate i's jump is listed: `restarted` 1 lists those of anchors whose V or A was set without P,
   0 the others, -1 all. */
static int jump_listed(const fmu_model *m, ln_int i, int restarted)
{
    if (!m->jump_counted[i]) return 0;
    const ln_int a = i / 3;
    return restarted < 0 || (!m->p_set[a] && m->va_vr[a] >= 0) == restarted;
}

/* The listed coordinates: each P's name, value reference, value, where the held motion had the anchor and the jump. */
static void jump_items(const fmu_model *m, int restarted, char *out, size_t n)
{
    const lnfmu_scene *s = m->s;
    int listed = 0, more = 0;
    for (ln_int i = 0; i < 3 * s->model->n_driven; i++) {
        if (!jump_listed(m, i, restarted)) continue;
        if (listed == JUMP_MAX_LISTED) {
            more++;
            continue;
        }
        append(out, n, "%s%s (valueReference %u) = %g m where the held motion had the anchor at %g m (a jump of %g m)",
               listed ? "; " : "", variable(s, m->p_vr[i])->name, m->p_vr[i], m->jump_P[i], m->jump_X[i],
               fabs(m->jump_P[i] - m->jump_X[i]));
        listed++;
    }
    if (more) append(out, n, "; and %d more", more);
}

/* The jump's impulse on the anchors with listed coordinates, by their Jreact names. */
static void jump_impulses(const fmu_model *m, int restarted, char *out, size_t n)
{
    const lnfmu_scene *s = m->s;
    int listed = 0;
    for (ln_int a = 0; a < s->model->n_driven; a++) {
        if (!(jump_listed(m, 3 * a, restarted) || jump_listed(m, 3 * a + 1, restarted)
              || jump_listed(m, 3 * a + 2, restarted)))
            continue;
        for (int e = 0; e < 3; e++, listed++)
            append(out, n, "%s%s = %g", listed ? ", " : "", variable(s, m->jreact_vr[3 * a + e])->name,
                   m->d->jump_impulse[3 * a + e]);
    }
}

/* The warning of a step that began with a position jump, into out (empty where nothing is to be said). */
static void say_position_jump(fmu_model *m, double t, char *out, size_t n)
{
    const ln_int n3 = 3 * m->s->model->n_driven;
    int moved_long = 0, moved_short = 0, restarted = 0;
    double shortest = INFINITY;
    for (ln_int i = 0; i < n3; i++) {
        if (jump_listed(m, i, 1)) restarted = 1;
        if (!jump_listed(m, i, 0)) continue;
        if (m->jump_long[i]) moved_long = 1;
        else moved_short = 1;
        shortest = ln_fmin(shortest, shortest_link_at(m, m->model.driven_idx[i / 3]));
    }
    out[0] = '\0';
    const int short_first = moved_short && !m->said_short_jump;
    if (moved_long || short_first) {
        char items[FMU_MESSAGE] = "", impulses[FMU_MESSAGE / 2] = "";
        jump_items(m, 0, items, sizeof items);
        jump_impulses(m, 0, impulses, sizeof impulses);
        append(out, n, "position jump at t=%g: %s. " JUMP_RELOCATION "%s N s. For a motion, set P, V and A together so "
               "that P continues the held motion P + V tau + A tau^2/2 (or give V and A as P's input derivatives).",
               t, items, impulses);
        if (short_first) {
            m->said_short_jump = 1;
            append(out, n, " Jumps shorter than a thousandth of the shortest link at the anchor (%g m here) are logged "
                   "once per instance, this one; longer ones every time.", JUMP_LOGGED_ALWAYS * shortest);
        }
    }
    if (restarted && !m->said_set_without_p) {
        m->said_set_without_p = 1;
        long vr = -1;
        for (ln_int i = 0; i < n3 && vr < 0; i++)
            if (jump_listed(m, i, 1)) vr = m->va_vr[i / 3];
        char items[FMU_MESSAGE] = "", impulses[FMU_MESSAGE / 2] = "";
        jump_items(m, 1, items, sizeof items);
        jump_impulses(m, 1, impulses, sizeof impulses);
        append(out, n, "%s%s (valueReference %ld) was set at t=%g without P of its anchor, so the held motion P + V tau "
               "+ A tau^2/2 restarted from the P last set: %s. This happens at every step where V or A is set without "
               "P, and is logged once per instance. " JUMP_RELOCATION "%s N s. Set P with V and A so that P continues "
               "the held motion (or give V and A as P's input derivatives).", out[0] ? " " : "",
               variable(m->s, (unsigned)vr)->name, vr, t, items, impulses);
    }
}

/* ---- parameters ---------------------------------------------------------------------------------- */

static int is_parameter(int kind) { return kind >= LNFMU_M && kind <= LNFMU_STEP; }

static int is_anchor_input(int kind) { return kind == LNFMU_P || kind == LNFMU_V || kind == LNFMU_A; }

static int is_input(int kind) { return kind == LNFMU_F || is_anchor_input(kind); }

/* The data's row of an anchor input: the held motion P + V s + A s^2/2 of the input-driven anchors. */
static double *anchor_input(const fmu_model *m, int kind)
{
    return kind == LNFMU_P ? m->d->drive_P : kind == LNFMU_V ? m->d->drive_V : m->d->drive_A;
}

static const char *input_quantity(int kind)
{
    return kind == LNFMU_P ? "position" : kind == LNFMU_V ? "velocity" : kind == LNFMU_A ? "acceleration" : "force";
}

/* The inputs as set (m->value) into the data: forces onto F_input, anchor motions onto the held drive. */
static void load_inputs(fmu_model *m)
{
    const lnfmu_scene *s = m->s;
    if (s->K) memset(m->d->F_input, 0, (size_t)(3 * s->K) * sizeof(double));
    for (ln_int vr = 0; vr < s->n_real; vr++) {
        const lnfmu_variable *v = &s->variables[vr];
        if (v->kind == LNFMU_F) m->d->F_input[v->index] = m->value[vr];
        else if (is_anchor_input(v->kind)) anchor_input(m, v->kind)[v->index] = m->value[vr];
    }
}

/* Why value is out of range for a parameter of this kind, or NULL (linknet_core's rules, baked). */
static const char *parameter_rule(const lnfmu_scene *s, int kind, double value, char *why, size_t n)
{
    if (!isfinite(value)) return "must be finite";
    switch (kind) {
    case LNFMU_M:
    case LNFMU_R:
    case LNFMU_STEP: return value > 0.0 ? NULL : "must be > 0";
    case LNFMU_TOLERANCE:
        if (value >= s->tolerance_min && value < s->tolerance_max) return NULL;
        snprintf(why, n, "must lie in [%g, %g) (below %g double precision cannot deliver it; from %g on the "
                 "projections onto the lengths can fail)", s->tolerance_min, s->tolerance_max, s->tolerance_min,
                 s->tolerance_max);
        return why;
    default: return NULL;
    }
}

/* Whether link l of the model is a rope (a ground's contacts are ropes too, linked after the scene's links). */
static int is_rope_link(const ln_model *model, ln_int l)
{
    for (ln_int r = 0; r < model->n_ropes; r++)
        if (model->rope_link[r] == l) return 1;
    return 0;
}

/* The relative violation of length R by link l at X: |distance / R - 1| for a rod; for a rope only its stretch
   beyond R, a rope being free to be shorter (UnilateralDynamics.initial_state). */
static double length_violation(const lnfmu_scene *s, const double *X, ln_int l, double R, double *distance)
{
    const ln_int a = s->model->k1[l], b = s->model->k2[l];
    double sq = 0.0;
    for (int e = 0; e < 3; e++) sq += (X[3 * b + e] - X[3 * a + e]) * (X[3 * b + e] - X[3 * a + e]);
    *distance = ln_sqrt(sq);
    const double relative = *distance / R - 1.0;
    return is_rope_link(s->model, l) ? ln_fmax(relative, 0.0) : fabs(relative);
}

/* The length R of link l against the initial positions: a relative violation beyond the scene's tolerance (a rope:
   stretched beyond it) is refused unless the scene opts in to projecting its initial positions. */
static int length_fits(const lnfmu_scene *s, ln_int l, double R, char *msg, const char *name)
{
    if (s->project_initial) return 1;
    double distance;
    const double violation = length_violation(s, s->X0, l, R, &distance);
    if (violation <= s->length_tol) return 1;
    char label[512];
    link_label(s, l, label, sizeof label);
    fail(msg, FMU_ERROR, "%s = %.17g does not fit the initial positions: %s spans %.6g m in them (relative "
         "violation %.3g, tolerance %g%s). Change the length back, or build the FMU from a scene with "
         "\"options\": {\"project_initial_positions\": true}; nothing set", name, R, label, distance, violation,
         s->length_tol,
         is_rope_link(s->model, l) ? "; a rope may be shorter than its length, never longer" : "");
    return 0;
}

/* The scene's masses (all K), lengths and gravity with the parameters of values applied. */
static void parameter_arrays(const fmu_model *m, const double *values, double *mass, double *R, double *g)
{
    const lnfmu_scene *s = m->s;
    if (s->K) memcpy(mass, s->mass, (size_t)s->K * sizeof(double));
    for (ln_int vr = 0; vr < s->n_real; vr++) {
        const lnfmu_variable *v = variable(s, (unsigned)vr);
        if (v->kind == LNFMU_M) mass[v->index] = values[vr];
        else if (v->kind == LNFMU_R) R[v->index] = values[vr];
        else if (v->kind == LNFMU_G) g[v->index] = values[vr];
    }
}

static int scene_defaults(const fmu_model *m, const double *values)
{
    const lnfmu_scene *s = m->s;
    for (ln_int vr = 0; vr < s->n_real; vr++) {
        const lnfmu_variable *v = variable(s, (unsigned)vr);
        if ((v->kind == LNFMU_M && values[vr] != s->mass[v->index])
            || (v->kind == LNFMU_R && values[vr] != s->length[v->index])
            || (v->kind == LNFMU_G && values[vr] != s->gravity[v->index]))
            return 0;
    }
    return 1;
}

static double parameter_value(const lnfmu_scene *s, const double *values, int kind)
{
    for (ln_int vr = 0; vr < s->n_real; vr++)
        if (s->variables[vr].kind == kind) return values[vr];
    return 0.0;
}

/* ---- building the model -------------------------------------------------------------------------- */

static double worst_violation(const ln_model *model, const double *X, ln_int *worst_link)
{
    double worst = 0.0;
    *worst_link = -1;
    for (ln_int l = 0; l < model->L; l++) {
        const ln_int a = model->k1[l], b = model->k2[l];
        double sq = 0.0;
        for (int e = 0; e < 3; e++) sq += (X[3 * b + e] - X[3 * a + e]) * (X[3 * b + e] - X[3 * a + e]);
        const double r = fabs(ln_sqrt(sq) / model->R[l] - 1.0);
        if (!(r <= worst)) {
            worst = r;
            *worst_link = l;
        }
    }
    return worst;
}

/* X onto the link lengths (11) along M^-1 C(X)^T mu, then U onto (12) at the new X (ln_project_state). */
static int project_state(fmu_model *m, double *X, double *U, int positions, char *msg)
{
    const int status = ln_project_state(&m->model, m->d, X, U, positions, PROJECTION_TOL, PROJECTION_ITERATIONS, NULL);
    if (status == LN_OK) return FMU_OK;
    if (positions && status == LN_PROJECTION_FAILED) {
        char label[512] = "a link";
        if (m->d->fail_link >= 0) link_label(m->s, m->d->fail_link, label, sizeof label);
        return fail(msg, FMU_ERROR, "the initial positions cannot be projected onto the link lengths (worst: %s, "
                    "residual %.3g relative): the lengths R do not fit the scene's geometry", label,
                    m->d->fail_residual);
    }
    return fail(msg, FMU_ERROR, "the initial state cannot be projected onto (11) and (12) (native status %d: %s)",
                status, ln_status_name(status));
}

/* The initial state of a scene with ropes or a ground for the model built: with the scene's masses and lengths the
   library's (gravity does not enter it); with others, the core's (ln_rope_initial_state, as UnilateralDynamics.
   initial_state: rods within the scene's tolerance of their lengths and ropes not stretched beyond it, else refused
   or, where the scene opts in, projected; then the inelastic impact on the ropes at their length and the masses on
   the ground). */
static int unilateral_initial_state(fmu_model *m, const double *values, char *msg)
{
    const lnfmu_scene *s = m->s;
    const size_t n3 = (size_t)(3 * s->K);
    int changed = 0;
    for (ln_int vr = 0; vr < s->n_real; vr++) {
        const lnfmu_variable *v = variable(s, (unsigned)vr);
        changed |= (v->kind == LNFMU_M && values[vr] != s->mass[v->index])
                   || (v->kind == LNFMU_R && values[vr] != s->length[v->index]);
    }
    double *X = m->X_init, *U = m->U_init;
    if (!changed) {
        if (n3) {
            memcpy(X, s->X_init, n3 * sizeof(double));
            memcpy(U, s->U_init, n3 * sizeof(double));
        }
        return FMU_OK;
    }
    if (n3) {
        memcpy(X, s->X0, n3 * sizeof(double));
        memcpy(U, s->U0, n3 * sizeof(double));
    }
    double worst = 0.0, distance;
    ln_int worst_link = -1;
    for (ln_int l = 0; l < s->L - s->model->n_contacts - s->model->n_grips; l++) {  /* the scene's own links */
        const double violation = length_violation(s, X, l, m->model.R[l], &distance);
        if (!(violation <= worst)) {
            worst = violation;
            worst_link = l;
        }
    }
    char label[512] = "a link";
    if (worst > s->length_tol && !s->project_initial) {
        link_label(s, worst_link, label, sizeof label);
        return fail(msg, FMU_ERROR, "the initial positions violate the link lengths by up to %.3g relative at %s "
                    "(tolerance %g; a rope may be shorter than its length, never longer)", worst, label, s->length_tol);
    }
    const int status = ln_rope_initial_state(&m->model, &m->method, m->d, X, U, worst > s->length_tol);
    if (status == LN_OK) return FMU_OK;
    if (status == LN_PROJECTION_FAILED && m->d->fail_link >= 0) link_label(s, m->d->fail_link, label, sizeof label);
    return fail(msg, FMU_ERROR, "the initial state cannot be made consistent with the lengths R and masses M (native "
                "status %d: %s; worst: %s): the lengths do not fit the scene's geometry", status,
                ln_status_name(status), label);
}

/* The model, method and initial state for the parameters in values and integrator. At the scene's defaults
   the baked ones; otherwise rebuilt here. On failure msg says why and the model is left half-built: the
   caller builds the previous parameters again. */
static int build_run(fmu_model *m, const double *values, ln_int integrator, char *msg)
{
    const lnfmu_scene *s = m->s;
    const ln_int K = s->K, L = s->L;
    const lnfmu_method *meth = &s->methods[integrator];
    m->method = meth->method;
    if (meth->adaptive) {
        m->method.rtol = m->method.atol = parameter_value(s, values, LNFMU_TOLERANCE);
    } else {
        m->method.dt = parameter_value(s, values, LNFMU_STEP);
    }
    m->model = *s->model;
    m->model.ldl = m->ldl;
    m->model.rigid = s->rigid;
    if (scene_defaults(m, values)) {
        if (K) {
            memcpy(m->X_init, s->X_init, (size_t)(3 * K) * sizeof(double));
            memcpy(m->U_init, s->U_init, (size_t)(3 * K) * sizeof(double));
        }
        if (m->n_bodies) memcpy(m->Y_init, s->Y0, (size_t)(LN_RIGID_STATE * m->n_bodies) * sizeof(double));
        return FMU_OK;
    }

    /* changed parameters: what depends on them, by the library's own function (as linknet_core builds its model) */
    double *mass = m->mass_full, *R = m->R, *g = m->gravity;
    if (L) memcpy(R, s->length, (size_t)L * sizeof(double));
    memcpy(g, s->gravity, 3 * sizeof(double));
    parameter_arrays(m, values, mass, R, g);
    if (ln_model_weights(&m->model, mass, R, g, s->force, m->weights) != LN_OK)
        return fail(msg, FMU_ERROR, "out of memory");
    if (s->model->n_ropes) return unilateral_initial_state(m, values, msg);

    /* the initial state, as Simulator prepares it: lengths checked (or projected), velocities onto (12) */
    double *X = m->X_init, *U = m->U_init;
    if (K) {
        memcpy(X, s->X0, (size_t)(3 * K) * sizeof(double));
        memcpy(U, s->U0, (size_t)(3 * K) * sizeof(double));
    }
    ln_int worst_link;
    const double worst = worst_violation(&m->model, X, &worst_link);
    if (worst > s->length_tol && !s->project_initial) {
        char label[512];
        link_label(s, worst_link, label, sizeof label);
        return fail(msg, FMU_ERROR, "the initial positions violate the link lengths by up to %.3g relative at %s "
                    "(tolerance %g)", worst, label, s->length_tol);
    }
    int result = project_state(m, X, U, worst > s->length_tol, msg);
    if (result != FMU_OK) return result;
    if (s->specialisation == LNFMU_STATIC) {
        for (ln_int i = 0; i < 3 * K; i++) U[i] = 0.0;  /* the only velocity (12) allows where nothing moves */
    } else if (s->specialisation == LNFMU_RIGID) {
        if (worst_violation(&m->model, X, &worst_link) > RESHAPE_TOL) {  /* bodies are frozen at exact lengths */
            result = project_state(m, X, U, 1, msg);
            if (result != FMU_OK) return result;
        }
        m->rigid.n_bodies = m->n_bodies;
        m->rigid.body_of = s->rigid->body_of;
        if (ln_rigid_layout(K, mass, X, U, &m->rigid, m->r, m->inertia, m->body_mass, m->top, m->Y_init) != LN_OK)
            return fail(msg, FMU_ERROR, "a rigid body has no mass");
        m->model.rigid = &m->rigid;
    }
    return FMU_OK;
}

/* build_run, and the companion's method, factor and goal for it (the core's rule, error_estimate.c). */
static int build(fmu_model *m, const double *values, ln_int integrator, char *msg)
{
    const int result = build_run(m, values, integrator, msg);
    if (result != FMU_OK) return result;
    const lnfmu_method *meth = &m->s->methods[integrator];
    double dt_c, rtol_c, atol_c;
    m->method_c = m->method;
    m->factor = ln_companion_settings(meth->adaptive, meth->order, m->method.dt, m->method.rtol, m->method.atol, &dt_c,
                                      &rtol_c, &atol_c);
    if (meth->adaptive) {
        m->method_c.rtol = rtol_c;
        m->method_c.atol = atol_c;
    } else {
        m->method_c.dt = dt_c;
    }
    m->goal = ln_error_goal(meth->adaptive, m->method.rtol, m->method.atol,
                            ln_scene_size(scene_masses(m->s), m->X_init));
    return FMU_OK;
}

/* One data (the run's or the companion's) at the current model's initial state, at the start time. */
static int start_data(fmu_model *m, ln_data *d, char *msg)
{
    const lnfmu_scene *s = m->s;
    const size_t n3 = (size_t)(3 * s->K);
    if (n3) {
        memcpy(d->X, m->X_init, n3 * sizeof(double));
        memcpy(d->U, m->U_init, n3 * sizeof(double));
    }
    d->t = m->start_time;
    d->drive_t0 = d->drive_hold_t = m->start_time;  /* scene motions run in t - t0; the hold starts now */
    if (s->model->n_driven) {
        memset(d->impulse, 0, (size_t)(3 * s->model->n_driven) * sizeof(double));
        memset(d->jump_impulse, 0, (size_t)(3 * s->model->n_driven) * sizeof(double));
    }
    d->jump_position = d->jump_velocity = 0.0;
    d->jumps = 0;
    d->h_next = s->h_next_init;
    d->planar = s->planar_init && m->model.planar;
    d->steps = d->rejected = d->n_rhs = 0;
    if (s->model->n_ropes) {  /* the mode is chosen from the state at the first advance; no impulse, no event yet */
        d->mode_chosen = 0;
        d->events_this_step = d->n_events = d->events_lost = 0;
        memset(d->rope_impulse, 0, (size_t)s->L * sizeof(double));
    }
    if (m->n_bodies) {
        if (ln_rigid_set_state(&m->model, d, m->Y_init) != LN_OK)
            return fail(msg, FMU_ERROR, "the initial rigid-body state is not finite");
        if (n3) {  /* as the library: the masses' state as given, the bodies' own agrees to round-off */
            memcpy(d->X, m->X_init, n3 * sizeof(double));
            memcpy(d->U, m->U_init, n3 * sizeof(double));
        }
    }
    return FMU_OK;
}

/* The run and its companion at the current model's initial state, at the start time, with the inputs as set. */
static int set_initial_state(fmu_model *m, char *msg)
{
    int result = start_data(m, m->d, msg);
    if (result == FMU_OK) result = start_data(m, m->dc, msg);
    m->events_logged = m->events_lost = 0;
    m->error = 0.0;
    m->over_goal = 0;
    m->stepped = 0;
    m->outputs_stale = m->interface_stale = 1;
    return result;
}

/* The inputs as set in the run's data (held forces, the input-driven anchors' hold and its start) into the
   companion's: the same inputs over the same step. */
static void companion_inputs(fmu_model *m)
{
    const ln_data *d = m->d;
    ln_data *dc = m->dc;
    const size_t n3 = (size_t)(3 * m->s->K), nd = (size_t)(3 * m->s->model->n_driven);
    if (n3) memcpy(dc->F_input, d->F_input, n3 * sizeof(double));
    if (nd) {
        memcpy(dc->drive_P, d->drive_P, nd * sizeof(double));
        memcpy(dc->drive_V, d->drive_V, nd * sizeof(double));
        memcpy(dc->drive_A, d->drive_A, nd * sizeof(double));
    }
    dc->drive_hold_t = d->drive_hold_t;
}

/* Apply the parameters as set: the model is rebuilt, the state starts again. On failure the previous
   parameters stay in force (and remain pending). */
static int apply_parameters(fmu_model *m, char *msg)
{
    const lnfmu_scene *s = m->s;
    int result = build(m, m->value, m->integrator, msg);
    if (result != FMU_OK) {
        char ignored[FMU_MESSAGE];
        build(m, m->applied, m->applied_integrator, ignored);  /* succeeded before */
        set_initial_state(m, ignored);
        return result;
    }
    memcpy(m->applied, m->value, (size_t)s->n_real * sizeof(double));
    m->applied_integrator = m->integrator;
    m->applied_estimate = m->estimate;
    m->dirty = 0;
    return set_initial_state(m, msg);
}

static void start_values(fmu_model *m)
{
    const lnfmu_scene *s = m->s;
    for (ln_int vr = 0; vr < s->n_real; vr++) {
        const lnfmu_variable *v = variable(s, (unsigned)vr);
        double x = 0.0;
        switch (v->kind) {
        case LNFMU_M: x = s->mass[v->index]; break;
        case LNFMU_R: x = s->length[v->index]; break;
        case LNFMU_G: x = s->gravity[v->index]; break;
        case LNFMU_TOLERANCE: x = s->default_tolerance; break;
        case LNFMU_STEP: x = s->default_step; break;
        case LNFMU_P: x = s->X0[3 * s->model->driven_idx[v->index / 3] + v->index % 3]; break;  /* at rest */
        default: break;
        }
        m->value[vr] = x;
    }
    m->integrator = s->default_method;
    m->estimate = s->default_estimate;
    m->start_time = 0.0;
    if (m->d) load_inputs(m);
}

/* ---- life cycle ---------------------------------------------------------------------------------- */

const fmu_model_info *fmu_model_info_get(const fmu_model *m) { return &m->info; }

void fmu_model_free(fmu_model *m)
{
    if (!m) return;
    lnfmu_scene_free((lnfmu_scene *)m->s);
    ln_data_free(m->d);
    ln_data_free(m->dc);
    ln_ldl_symbolic_free(m->ldl);
    double *arrays[] = {m->value, m->applied, m->R, m->weights, m->r, m->inertia, m->body_mass, m->mass_full,
                        m->gravity, m->X_init, m->U_init, m->Y_init, m->Xo, m->Uo, m->Ys, m->peak};
    for (size_t i = 0; i < sizeof arrays / sizeof arrays[0]; i++) free(arrays[i]);
    free(m->top);
    free(m->p_set);
    free(m->va_vr);
    free(m->p_vr);
    free(m->jreact_vr);
    free(m->jump_P);
    free(m->jump_X);
    free(m->jump_counted);
    free(m->jump_long);
    ln_interface_free(m->interface);
    double *seeds[] = {m->seed_F, m->seed_P, m->seed_V, m->seed_A, m->dT, m->dFreact};
    for (size_t i = 0; i < sizeof seeds / sizeof seeds[0]; i++) free(seeds[i]);
    free(m);
}

static double *doubles(ln_int n) { return calloc((size_t)(n > 0 ? n : 1), sizeof(double)); }

fmu_model *fmu_model_new(const fmu_resource *r, char *msg)
{
    const lnfmu_scene *s = lnfmu_scene_load(r, msg);
    if (!s) return NULL;
    fmu_model *m = calloc(1, sizeof *m);
    if (!m) {
        lnfmu_scene_free((lnfmu_scene *)s);
        fail(msg, FMU_ERROR, "out of memory");
        return NULL;
    }
    m->s = s;
    m->info.model_identifier = s->model_identifier;
    m->info.guid = s->guid;
    m->info.fingerprint = s->fingerprint;
    m->info.n_real = (unsigned)s->n_real;
    m->info.n_string = 1;   /* integrator */
    m->info.n_boolean = 1;  /* estimate_error */
    m->info.events = s->model->n_ropes > 0;
    const ln_int K = s->K, L = s->L, P = s->model->n_pairs;
    m->n_bodies = s->rigid ? s->rigid->n_bodies : 0;
    const ln_int B = m->n_bodies;
    m->value = doubles(s->n_real);
    m->applied = doubles(s->n_real);
    m->R = doubles(L);
    m->weights = doubles(ln_model_weights_size(s->model));
    m->r = doubles(3 * K);
    m->inertia = doubles(3 * B);
    m->body_mass = doubles(B);
    m->top = calloc((size_t)(B > 0 ? B : 1), sizeof(ln_int));
    m->mass_full = doubles(K);
    m->gravity = doubles(3);
    m->X_init = doubles(3 * K);
    m->U_init = doubles(3 * K);
    m->Y_init = doubles(LN_RIGID_STATE * B);
    m->Xo = doubles(3 * K);
    m->Uo = doubles(3 * K);
    m->Ys = doubles(LN_RIGID_STATE * B);
    m->peak = doubles(2 * L);
    const size_t nd = (size_t)(s->model->n_driven > 0 ? s->model->n_driven : 1);
    m->p_set = calloc(nd, 1);
    m->va_vr = calloc(nd, sizeof *m->va_vr);
    m->p_vr = calloc(3 * nd, sizeof *m->p_vr);
    m->jreact_vr = calloc(3 * nd, sizeof *m->jreact_vr);
    m->jump_P = doubles(3 * (ln_int)nd);
    m->jump_X = doubles(3 * (ln_int)nd);
    m->jump_counted = calloc(3 * nd, 1);
    m->jump_long = calloc(3 * nd, 1);
    if (!(m->value && m->applied && m->R && m->weights && m->r && m->inertia && m->body_mass && m->top
          && m->mass_full && m->gravity && m->X_init && m->U_init && m->Y_init && m->Xo && m->Uo && m->Ys && m->peak
          && m->p_set
          && m->va_vr && m->p_vr && m->jreact_vr && m->jump_P && m->jump_X && m->jump_counted && m->jump_long)) {
        fmu_model_free(m);
        fail(msg, FMU_ERROR, "out of memory");
        return NULL;
    }
    for (size_t i = 0; i < 3 * nd; i++) m->p_vr[i] = m->jreact_vr[i] = (unsigned)s->n_real;
    for (ln_int vr = 0; vr < s->n_real; vr++) {
        const lnfmu_variable *v = variable(s, (unsigned)vr);
        if (v->kind == LNFMU_P) m->p_vr[v->index] = (unsigned)vr;
        if (v->kind == LNFMU_JREACT) m->jreact_vr[v->index] = (unsigned)vr;
    }
    clear_anchor_marks(m);
    if (s->model->solver == LN_SOLVER_LDL) {
        /* the symbolic analysis of A's pattern, in the order the library's structure analysis chose */
        m->ldl = ln_ldl_analyse(L, P, s->model->pair_first, s->model->pair_second, s->ldl_ordering);
        if (!m->ldl) {
            fmu_model_free(m);
            fail(msg, FMU_ERROR, "the sparse LDL^T analysis of the tension matrix failed (out of memory)");
            return NULL;
        }
    }
    ln_int stages = 0;  /* each method's own stages, or the rows its screen of the ropes' forces takes */
    for (ln_int i = 0; i < s->n_methods; i++) {
        const ln_method *method = &s->methods[i].method;
        const ln_int rows = ln_midpoint_rows(s->model, method);
        if (method->n_stages > stages) stages = method->n_stages;
        if (rows > stages) stages = rows;
    }
    m->model = *s->model;
    m->model.ldl = m->ldl;
    m->model.rigid = s->rigid;
    m->d = ln_data_new(&m->model, stages);
    m->dc = ln_data_new(&m->model, stages);
    if (!m->d || !m->dc) {
        fmu_model_free(m);
        fail(msg, FMU_ERROR, "the native core could not allocate its data (out of memory)");
        return NULL;
    }
    start_values(m);
    memcpy(m->applied, m->value, (size_t)s->n_real * sizeof(double));
    m->applied_integrator = m->integrator;
    m->applied_estimate = m->estimate;
    if (build(m, m->value, m->integrator, msg) != FMU_OK || set_initial_state(m, msg) != FMU_OK) {
        fmu_model_free(m);
        return NULL;
    }
    return m;
}

int fmu_model_reset(fmu_model *m, char *msg)
{
    start_values(m);
    clear_anchor_marks(m);
    m->said_short_jump = m->said_set_without_p = 0;
    m->dirty = 0;
    const int result = build(m, m->value, m->integrator, msg);
    if (result != FMU_OK) return result;
    memcpy(m->applied, m->value, (size_t)m->s->n_real * sizeof(double));
    m->applied_integrator = m->integrator;
    m->applied_estimate = m->estimate;
    return set_initial_state(m, msg);
}

int fmu_model_set_start_time(fmu_model *m, double start_time, char *msg)
{
    (void)msg;
    m->start_time = start_time;
    m->d->t = m->dc->t = start_time;  /* the scene's initial state, at t0 */
    m->d->drive_t0 = m->d->drive_hold_t = m->dc->drive_t0 = m->dc->drive_hold_t = start_time;
    m->outputs_stale = m->interface_stale = 1;
    return FMU_OK;
}

double fmu_model_time(const fmu_model *m) { return m->d->t; }

void lnfmu_core(fmu_model *m, const ln_model **model, const ln_method **method, ln_data **data)
{
    *model = &m->model;
    *method = &m->method;
    *data = m->d;
}

/* ---- values -------------------------------------------------------------------------------------- */

static int evaluate_outputs(fmu_model *m, char *msg)
{
    const lnfmu_scene *s = m->s;
    const size_t n3 = (size_t)(3 * s->K);
    if (n3) {
        memcpy(m->Xo, m->d->X, n3 * sizeof(double));
        memcpy(m->Uo, m->d->U, n3 * sizeof(double));
    }
    const int status = ln_evaluate(&m->model, m->d, m->Xo, m->Uo);
    if (status != LN_OK) {
        for (ln_int l = 0; l < s->L; l++) m->d->T[l] = NAN;
        for (ln_int i = 0; i < 3 * s->model->n_fixed; i++) m->d->reaction[i] = NAN;
        return fail(msg, FMU_ERROR, "the tensions (25)-(26) cannot be evaluated at t=%.17g (native status %d)",
                    m->d->t, status);
    }
    m->outputs_stale = 0;
    return FMU_OK;
}

int fmu_model_get_real(fmu_model *m, const unsigned *vr, size_t n, double *value, int initialized, char *msg)
{
    const lnfmu_scene *s = m->s;
    for (size_t i = 0; i < n; i++)
        if (vr[i] >= (unsigned)s->n_real)
            return fail(msg, FMU_ERROR, "value reference %u is not a Real variable of this FMU (Reals are 0..%lld%s)",
                        vr[i], (long long)(s->n_real - 1),
                        vr[i] == (unsigned)s->n_real ? "; it is the String parameter integrator" : "");
    if (m->dirty && !initialized) {
        /* initial unknowns read in initialization mode depend on the parameters set (ModelStructure) */
        const int result = apply_parameters(m, msg);
        if (result != FMU_OK) return result;
    }
    int result = FMU_OK;
    const ln_data *d = m->d;
    for (size_t i = 0; i < n; i++) {
        const lnfmu_variable *v = variable(s, vr[i]);
        switch (v->kind) {
        case LNFMU_X: value[i] = d->X[v->index]; break;
        case LNFMU_U: value[i] = d->U[v->index]; break;
        case LNFMU_JREACT: value[i] = d->impulse[v->index]; break;
        case LNFMU_ERROR_ESTIMATE: value[i] = m->applied_estimate ? m->error : NAN; break;
        case LNFMU_T_PEAK:
        case LNFMU_T_PEAK_TIME:
            if (m->stepped) {
                value[i] = m->peak[(v->kind == LNFMU_T_PEAK_TIME ? s->L : 0) + v->index];
                break;
            }
            /* before the first step: T at the start with the inputs as set, and the start time */
            if (m->outputs_stale && result == FMU_OK) result = evaluate_outputs(m, msg);
            value[i] = v->kind == LNFMU_T_PEAK ? d->T[v->index] : d->t;
            break;
        case LNFMU_T:
        case LNFMU_FREACT:
            if (m->outputs_stale && result == FMU_OK) result = evaluate_outputs(m, msg);
            value[i] = v->kind == LNFMU_T ? d->T[v->index] : d->reaction[v->index];
            break;
        case LNFMU_SLACK:  /* the library's rule (unilateral.slack_links): a rope whose tension is exactly 0, which
                              the state's mode gives every slack rope */
            if (m->outputs_stale && result == FMU_OK) result = evaluate_outputs(m, msg);
            value[i] = isnan(d->T[v->index]) ? NAN : d->T[v->index] == 0.0 ? 1.0 : 0.0;
            break;
        case LNFMU_JROPE: value[i] = d->rope_impulse[v->index]; break;
        default: value[i] = m->value[vr[i]]; break;
        }
    }
    return result;
}

int fmu_model_set_real(fmu_model *m, const unsigned *vr, size_t n, const double *value, int initialized, char *msg)
{
    const lnfmu_scene *s = m->s;
    /* all checked first: a refused call changes nothing */
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= (unsigned)s->n_real)
            return fail(msg, FMU_ERROR, "value reference %u is not a Real variable of this FMU (Reals are 0..%lld%s); "
                        "nothing set", vr[i], (long long)(s->n_real - 1),
                        vr[i] == (unsigned)s->n_real ? "; it is the String parameter integrator" : "");
        const lnfmu_variable *v = variable(s, vr[i]);
        const double x = value[i];
        if (v->kind == LNFMU_F) {
            if (!isfinite(x))
                return fail(msg, FMU_ERROR, "%s = %g is not a finite force; nothing set (the inputs keep their "
                            "values)", v->name, x);
            if (s->max_force > 0.0 && fabs(x) > s->max_force)
                return fail(msg, FMU_ERROR, "%s = %g N: forces beyond %g N would overflow the solver; nothing set "
                            "(the inputs keep their values)", v->name, x, s->max_force);
        } else if (is_anchor_input(v->kind)) {
            if (!isfinite(x))
                return fail(msg, FMU_ERROR, "%s = %g is not a finite %s; nothing set (the inputs keep their values)",
                            v->name, x, input_quantity(v->kind));
            if (s->max_force > 0.0 && fabs(x) > s->max_force)  /* the library's bound on anchor inputs too */
                return fail(msg, FMU_ERROR, "%s = %g: an anchor's %s beyond %g would overflow the solver; nothing set "
                            "(the inputs keep their values)", v->name, x, input_quantity(v->kind), s->max_force);
        } else if (!is_parameter(v->kind)) {
            return fail(msg, FMU_ERROR, "%s is an output and cannot be set (value %.17g); nothing set", v->name, x);
        } else if (initialized) {
            if (x != m->value[vr[i]])
                return fail(msg, FMU_ERROR, "%s is a fixed parameter and cannot be changed after initialization "
                            "(value %.17g, current %.17g); nothing set (fmi2Reset starts again)", v->name, x,
                            m->value[vr[i]]);
        } else {
            char why[256];
            const char *rule = parameter_rule(s, v->kind, x, why, sizeof why);
            if (rule) return fail(msg, FMU_ERROR, "parameter %s = %.17g %s; nothing set", v->name, x, rule);
            if (v->kind == LNFMU_R && !length_fits(s, v->index, x, msg, v->name)) return FMU_ERROR;
        }
    }
    for (size_t i = 0; i < n; i++) {
        const lnfmu_variable *v = variable(s, vr[i]);
        if (v->kind == LNFMU_F) {
            m->value[vr[i]] = value[i];
            m->d->F_input[v->index] = value[i];
            m->outputs_stale = m->interface_stale = 1;
        } else if (is_anchor_input(v->kind)) {
            /* P, V, A set at t: the anchor moves as P + V s + A s^2/2, s = t' - t, from now until they are set
               again (reads between a step and the next inputs see where that motion took it) */
            m->value[vr[i]] = value[i];
            anchor_input(m, v->kind)[v->index] = value[i];
            m->d->drive_hold_t = m->d->t;
            m->outputs_stale = m->interface_stale = 1;
            const ln_int a = v->index / 3;  /* which of the anchor's inputs were set: see position jumps */
            if (v->kind == LNFMU_P) m->p_set[a] = 1;
            else if (m->va_vr[a] < 0) m->va_vr[a] = (long)vr[i];
        } else if (value[i] != m->value[vr[i]]) {
            m->value[vr[i]] = value[i];
            m->dirty = 1;
        }
    }
    return FMU_OK;
}

/* The input an anchor position's derivative of order 1 (V) or 2 (A) sets: its value reference, or -1 for an
   input held constant over a step. The layout puts P, V, A of an anchor at the same index. */
static long derivative_target(const lnfmu_scene *s, unsigned vr, int order)
{
    const lnfmu_variable *v = variable(s, vr);
    if (v->kind != LNFMU_P || (order != 1 && order != 2)) return -1;
    const int kind = order == 1 ? LNFMU_V : LNFMU_A;
    for (ln_int w = 0; w < s->n_real; w++)
        if (s->variables[w].kind == kind && s->variables[w].index == v->index) return (long)w;
    return -1;
}

int fmu_model_set_real_input_derivatives(fmu_model *m, const unsigned *vr, size_t n, const int *order,
                                         const double *value, int initialized, char *msg)
{
    const lnfmu_scene *s = m->s;
    /* all checked first: a refused call changes nothing */
    size_t held = n;  /* the first input held constant whose derivative is ignored */
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= (unsigned)s->n_real)
            return fail(msg, FMU_ERROR, "value reference %u is not a Real variable of this FMU (Reals are 0..%lld); "
                        "nothing set", vr[i], (long long)(s->n_real - 1));
        const lnfmu_variable *v = variable(s, vr[i]);
        if (!is_input(v->kind))
            return fail(msg, FMU_ERROR, "%s is %s, not an input: it takes no input derivative; nothing set", v->name,
                        is_parameter(v->kind) ? "a parameter" : "an output");
        if (order[i] != 1 && order[i] != 2)
            return fail(msg, FMU_ERROR, "derivative of order %d of %s refused: inputs take derivatives of order 1 "
                        "and 2 only; nothing set", order[i], v->name);
        if (v->kind == LNFMU_P) {
            const char *what = input_quantity(order[i] == 1 ? LNFMU_V : LNFMU_A);
            if (!isfinite(value[i]))
                return fail(msg, FMU_ERROR, "derivative of order %d of %s = %g is not a finite %s; nothing set",
                            order[i], v->name, value[i], what);
            if (s->max_force > 0.0 && fabs(value[i]) > s->max_force)
                return fail(msg, FMU_ERROR, "derivative of order %d of %s = %g: an anchor's %s beyond %g would "
                            "overflow the solver; nothing set", order[i], v->name, value[i], what, s->max_force);
        } else if (held == n) {
            held = i;
        }
    }
    for (size_t i = 0; i < n; i++) {
        const long target = derivative_target(s, vr[i], order[i]);
        if (target < 0) continue;
        const unsigned t = (unsigned)target;
        const int result = fmu_model_set_real(m, &t, 1, &value[i], initialized, msg);
        if (result != FMU_OK) return result;  /* checked above: not reached */
    }
    if (held < n)
        return fail(msg, FMU_WARNING, "%s is held constant over a communication step: its derivative of order %d "
                    "(%g) is ignored%s", variable(s, vr[held])->name, order[held], value[held],
                    n > 1 ? " (as are those of any other input but an anchor's position P in this call)" : "");
    return FMU_OK;
}

/* ---- directional derivatives ------------------------------------------------------------------- */

static int is_output(int kind)
{
    return kind == LNFMU_X || kind == LNFMU_U || kind == LNFMU_T || kind == LNFMU_FREACT || kind == LNFMU_JREACT
           || kind == LNFMU_ERROR_ESTIMATE || kind == LNFMU_T_PEAK || kind == LNFMU_T_PEAK_TIME || kind == LNFMU_SLACK
           || kind == LNFMU_JROPE;
}

/* What a variable that is not of the role asked is, for a refusal. */
static const char *role_of(int kind)
{
    return is_input(kind) ? "an input" : is_parameter(kind) ? "a parameter" : "an output";
}

/* The seeds and results of directional derivatives, and the core's workspace: made at the first call. */
static int interface_workspace(fmu_model *m, char *msg)
{
    if (m->interface) return FMU_OK;
    const ln_int K3 = 3 * m->s->K, n3 = 3 * m->s->model->n_driven;
    m->seed_F = doubles(K3);
    m->seed_P = doubles(n3);
    m->seed_V = doubles(n3);
    m->seed_A = doubles(n3);
    m->dT = doubles(m->s->L);
    m->dFreact = doubles(3 * m->s->model->n_fixed);
    if (m->seed_F && m->seed_P && m->seed_V && m->seed_A && m->dT && m->dFreact)
        m->interface = ln_interface_new(&m->model);
    if (m->interface) return FMU_OK;
    return fail(msg, FMU_ERROR, "out of memory for the interface linearization");
}

/* The derivatives of the outputs unknown[] along the seed seed[] on the inputs known[], at the current state with the
   inputs as set: one seed, one derivative of the tension system (25)-(26) by the core (ln_interface_directional),
   with the linearization prepared once per state and inputs (ln_interface_prepare). X, U, Jreact and the error
   estimate have no direct feedthrough (ModelStructure): their derivatives are 0. A known reference listed twice
   adds its seeds (the derivative is linear in the seed). */
int fmu_model_directional_derivative(fmu_model *m, const unsigned *unknown, size_t n_unknown, const unsigned *known,
                                     size_t n_known, const double *seed, double *derivative, char *msg)
{
    const lnfmu_scene *s = m->s;
    /* all checked first: a refused call writes nothing */
    for (size_t i = 0; i < n_known; i++) {
        if (known[i] >= (unsigned)s->n_real)
            return fail(msg, FMU_ERROR, "known value reference %u is not a Real variable of this FMU (Reals are "
                        "0..%lld): a directional derivative is taken with respect to the inputs F, P, V, A", known[i],
                        (long long)(s->n_real - 1));
        const lnfmu_variable *v = variable(s, known[i]);
        if (!is_input(v->kind))
            return fail(msg, FMU_ERROR, "known %s (value reference %u) is %s, not an input: a directional derivative "
                        "is taken with respect to the inputs F, P, V, A", v->name, known[i], role_of(v->kind));
        if (!isfinite(seed[i]))
            return fail(msg, FMU_ERROR, "the seed dvKnown of %s (value reference %u) is %g: a seed must be finite",
                        v->name, known[i], seed[i]);
    }
    int feedthrough = 0;
    for (size_t i = 0; i < n_unknown; i++) {
        if (unknown[i] >= (unsigned)s->n_real)
            return fail(msg, FMU_ERROR, "unknown value reference %u is not a Real variable of this FMU (Reals are "
                        "0..%lld): a directional derivative is that of an output", unknown[i],
                        (long long)(s->n_real - 1));
        const lnfmu_variable *v = variable(s, unknown[i]);
        if (!is_output(v->kind))
            return fail(msg, FMU_ERROR, "unknown %s (value reference %u) is %s, not an output: a directional "
                        "derivative is that of an output (X, U, T, T_peak, T_peak_time, Freact, Jreact, "
                        "error_estimate, slack, Jrope)", v->name, unknown[i], role_of(v->kind));
        feedthrough |= v->kind == LNFMU_T || v->kind == LNFMU_FREACT;
    }
    if (s->linearization_refusal[0])  /* the library's reason (ropes: the rods' linearization holds in one mode) */
        return fail(msg, FMU_ERROR, "%s", s->linearization_refusal);
    if (!feedthrough) {  /* no output asked has direct feedthrough */
        for (size_t i = 0; i < n_unknown; i++) derivative[i] = 0.0;
        return FMU_OK;
    }
    int result = interface_workspace(m, msg);
    if (result != FMU_OK) return result;
    if (m->interface_stale) {
        const int status = ln_interface_prepare(&m->model, m->interface, m->d, m->d->X, m->d->U, m->d->F_input);
        if (status != LN_OK)
            return fail(msg, FMU_ERROR, "the tension system (25)-(26) cannot be linearized at t=%.17g (native status "
                        "%d: %s)", m->d->t, status, ln_status_name(status));
        m->interface_stale = 0;
    }
    const size_t K3 = (size_t)(3 * s->K), n3 = (size_t)(3 * s->model->n_driven);
    memset(m->seed_F, 0, (K3 ? K3 : 1) * sizeof(double));
    if (n3) {
        memset(m->seed_P, 0, n3 * sizeof(double));
        memset(m->seed_V, 0, n3 * sizeof(double));
        memset(m->seed_A, 0, n3 * sizeof(double));
    }
    for (size_t i = 0; i < n_known; i++) {
        const lnfmu_variable *v = variable(s, known[i]);
        double *slot = v->kind == LNFMU_F ? m->seed_F : v->kind == LNFMU_P ? m->seed_P
                       : v->kind == LNFMU_V ? m->seed_V : m->seed_A;
        slot[v->index] += seed[i];
    }
    const int status = ln_interface_directional(&m->model, m->interface, m->seed_F, m->seed_P, m->seed_V, m->seed_A,
                                                m->dT, m->dFreact, NULL);
    if (status != LN_OK)
        return fail(msg, FMU_ERROR, "the directional derivative at t=%.17g is not finite (native status %d: %s)",
                    m->d->t, status, ln_status_name(status));
    for (size_t i = 0; i < n_unknown; i++) {
        const lnfmu_variable *v = variable(s, unknown[i]);
        derivative[i] = v->kind == LNFMU_T ? m->dT[v->index] : v->kind == LNFMU_FREACT ? m->dFreact[v->index] : 0.0;
    }
    return FMU_OK;
}

int fmu_model_get_string(fmu_model *m, const unsigned *vr, size_t n, const char **value, char *msg)
{
    const lnfmu_scene *s = m->s;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != (unsigned)s->n_real)
            return fail(msg, FMU_ERROR, "value reference %u is not a String variable of this FMU (the only one is "
                        "integrator, %lld)", vr[i], (long long)s->n_real);
        value[i] = s->methods[m->integrator].name;
    }
    return FMU_OK;
}

int fmu_model_set_string(fmu_model *m, const unsigned *vr, size_t n, const char *const *value, int initialized,
                         char *msg)
{
    const lnfmu_scene *s = m->s;
    ln_int chosen = m->integrator;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != (unsigned)s->n_real)
            return fail(msg, FMU_ERROR, "value reference %u is not a String variable of this FMU (the only one is "
                        "integrator, %lld); nothing set", vr[i], (long long)s->n_real);
        ln_int found = -1;
        for (ln_int k = 0; value[i] && k < s->n_methods; k++)
            if (strcmp(value[i], s->methods[k].name) == 0) found = k;
        if (found < 0) {
            char names[512] = "";
            for (ln_int k = 0; k < s->n_methods; k++) {
                strncat(names, s->methods[k].name, sizeof names - strlen(names) - 3);
                if (k + 1 < s->n_methods) strncat(names, ", ", sizeof names - strlen(names) - 1);
            }
            return fail(msg, FMU_ERROR, "parameter integrator = \"%s\" is not one of %s; nothing set",
                        value[i] ? value[i] : "(null)", names);
        }
        if (initialized && found != m->integrator)
            return fail(msg, FMU_ERROR, "integrator is a fixed parameter and cannot be changed after initialization "
                        "(\"%s\", current \"%s\"); nothing set", value[i], s->methods[m->integrator].name);
        chosen = found;
    }
    if (chosen != m->integrator) {
        m->integrator = chosen;
        m->dirty = 1;
    }
    return FMU_OK;
}

/* ---- stepping ------------------------------------------------------------------------------------ */

int fmu_model_initialize(fmu_model *m, char *msg)
{
    if (!m->dirty) return FMU_OK;
    return apply_parameters(m, msg);
}

/* stages/rattle.c: a fixed step whose position stage or implicit half kick fails is taken again as 2, 4, ...,
   2^ln_max_split_level equal sub-steps before the advance gives up. */
extern const int ln_max_split_level;

/* Why no retry of a step that failed with `status` can succeed from this state with these inputs, however short
   the master makes the step, into out (n bytes): 1; or 0 where a shorter step may succeed: more steps than one
   advance takes (the message names the longest interval that is not), a state that became non-finite or a
   singular configuration or a driven anchor's motion that failed somewhere within the step (a shorter one may end
   before), a step of free rigid bodies (their engine does not split a failing step), memory. */
static int no_retry_helps(const fmu_model *m, int status, char *out, size_t n)
{
    switch (status) {
    case LN_STEP_UNDERFLOW:
        snprintf(out, n, "the error-controlled integrator already cut its own steps down to 16 ulps of t");
        return 1;
    case LN_PROJECTION_FAILED:
    case LN_IMPLICIT_KICK_FAILED:
        if (m->model.rigid) return 0;
        if (m->method.kind == LN_COMPOSITION)
            snprintf(out, n, "the integrator already took the failing step again as up to %d equal sub-steps, and "
                     "its own step is the parameter step, fixed during a run%s", 1 << ln_max_split_level,
                     m->model.n_driven ? " (a failure where the driven anchors jump to new inputs does not depend "
                                         "on the step at all)" : "");
        else  /* the Runge-Kutta steps reject and shorten a step whose projection fails: only the jump is left */
            snprintf(out, n, "the driven anchors' jump to their new inputs could not be followed, which does not "
                     "depend on the step (the error-controlled integrator shortens its own steps where a "
                     "projection fails)");
        return 1;
    default:
        return 0;
    }
}

/* The companion's step after the run's (the error estimate): FMU_OK, or FMU_NOTE with the note in note (n bytes). */
static int companion_step(fmu_model *m, double t_fmu, double t_target, char *note, size_t n)
{
    const lnfmu_scene *s = m->s;
    if (!m->applied_estimate || !isfinite(m->error)) return FMU_OK;  /* off, or the companion failed before */

    /* the companion: the same step with the same inputs, at its own settings */
    companion_inputs(m);
    const int companion = ln_companion_advance(&m->model, &m->method_c, m->dc, t_target, s->max_steps);
    if (m->model.n_ropes) {  /* the companion's events are not the run's: its log is emptied unread */
        ln_rope_events_drained(m->dc);
        m->dc->events_lost = 0;
    }
    if (companion != LN_OK) {
        /* the run's own result stands; the estimate is +inf from here on (until a reset or a restored state). The
           words are the library's (Simulator.error_note), the reason the core's (ln_explain) */
        char why[FMU_MESSAGE - 512], label[512] = "";
        if (m->dc->fail_link >= 0) link_label(s, m->dc->fail_link, label, sizeof label);
        ln_explain(&m->model, &m->method_c, m->dc, companion, t_fmu, t_target, s->max_steps, label, why, sizeof why);
        m->error = INFINITY;
        m->over_goal = 1;
        char where[FMU_MESSAGE - 256];
        snprintf(where, sizeof where, "at t = %g s: %s", m->dc->t, why);
        ln_estimate_failure_text(s->scene_name, where, note, n);
        return FMU_NOTE;
    }
    m->error = m->factor * ln_position_gap(scene_masses(s), m->d->X, m->dc->X);
    const int over = m->error > m->goal;
    const int crossing = over && !m->over_goal;
    m->over_goal = over;
    if (!crossing) return FMU_OK;
    /* the library's words (the core's ln_accuracy_text); said again only after the estimate came back */
    ln_accuracy_text(s->scene_name, t_target, m->error, m->goal, 0.0, note, n);
    return FMU_NOTE;
}

int fmu_model_do_step(fmu_model *m, double t, double h, char *msg)
{
    const lnfmu_scene *s = m->s;
    const double t_fmu = m->d->t, t_target = t + h;
    m->events_logged = m->events_lost = 0;
    if (t_target <= t_fmu) return FMU_OK;  /* h below half an ulp of t: nothing to integrate */
    const int jumped = position_jump(m);
    const int status = ln_advance(&m->model, &m->method, m->d, t_target, s->max_steps);
    if (status != LN_OK) {
        char why[FMU_MESSAGE], label[512] = "", final[320] = "";
        if (m->d->fail_link >= 0) link_label(s, m->d->fail_link, label, sizeof label);
        /* a fixed-step method's count is known before any step: the span, dt, the count and the limit, as the
           library says them */
        if (!(status == LN_TOO_MANY_STEPS && m->method.kind == LN_COMPOSITION
              && ln_step_count_problem(t_fmu, t_target, m->method.dt, s->max_steps, why, sizeof why)))
            ln_explain(&m->model, &m->method, m->d, status, t_fmu, t_target, s->max_steps, label, why, sizeof why);
        if (jumped) {  /* the inputs that jumped, and the rule (the pythonfmu FMU's words, anchor_jumps.failure_note) */
            char items[FMU_MESSAGE] = "";
            jump_items(m, -1, items, sizeof items);
            append(why, sizeof why, ". The step began with a position jump: %s; " JUMP_RULE, items);
        }
        if (no_retry_helps(m, status, final, sizeof final))
            return fail(msg, FMU_DISCARD_FINAL, "step from t=%.17g with h=%.17g failed, the FMU stays at t=%.17g: %s. "
                        "No retry of this step can succeed, however short: %s", t, h, t_fmu, why, final);
        return fail(msg, FMU_DISCARD, "step from t=%.17g with h=%.17g failed, the FMU stays at t=%.17g: %s", t, h,
                    t_fmu, why);
    }
    m->outputs_stale = m->interface_stale = 1;
    if (m->model.n_ropes) {  /* the step's events, kept in the data's log for the glue to log */
        m->events_logged = ln_rope_events_drained(m->d);
        m->events_lost = m->d->events_lost;
        m->d->events_lost = 0;
    }
    /* the step's tension peaks; where the path located none (a static scene, free rigid bodies), or with ropes or a
       ground, whose modes change the tensions' meaning at the events (the library's rule, locates_peaks), T at the
       step's end under its inputs, evaluated now */
    const int located = !m->model.n_ropes && ln_tension_peaks_located(m->d);
    if (!located) {
        char ignored[FMU_MESSAGE];
        evaluate_outputs(m, ignored);  /* a failure leaves T NaN, and says so when T is read */
    }
    ln_tension_peaks(&m->model, m->d, located, m->peak, m->peak + s->L);
    m->stepped = 1;
    char warning[FMU_MESSAGE] = "", note[FMU_MESSAGE - 64] = "";
    if (jumped) say_position_jump(m, t, warning, sizeof warning);
    clear_anchor_marks(m);
    const int result = companion_step(m, t_fmu, t_target, note, sizeof note);
    /* a position jump is a warning; a note of the error estimate in the same step is said after it */
    if (warning[0]) return fail(msg, FMU_WARNING, "%s%s%s", warning, result == FMU_NOTE ? " " : "",
                                result == FMU_NOTE ? note : "");
    if (result == FMU_NOTE) return fail(msg, FMU_NOTE, "%s", note);
    return FMU_OK;
}

/* x as Python's repr writes a float (the fewest significant digits that read back as x; positional from 1e-4 to
   1e16, with ".0" on a whole number), so that the log's times are those of the pythonfmu FMU's messages
   (fmu_src/linknet_fmu/rope_events.py: event_message). */
static void python_repr(double x, char *out, size_t n)
{
    if (!isfinite(x)) {
        snprintf(out, n, "%s", isnan(x) ? "nan" : x > 0 ? "inf" : "-inf");
        return;
    }
    int digits = 1;
    for (; digits < 17; digits++) {
        snprintf(out, n, "%.*e", digits - 1, x);
        if (strtod(out, NULL) == x) break;
    }
    snprintf(out, n, "%.*e", digits - 1, x);
    const int exponent = atoi(strchr(out, 'e') + 1);
    if (exponent < -4 || exponent >= 16) return;  /* "1.5e-05": Python's form too */
    const int decimals = digits - 1 - exponent;
    snprintf(out, n, "%.*f", decimals > 0 ? decimals : 0, x);
    if (!strchr(out, '.')) append(out, n, ".0");
}

int fmu_model_event(const fmu_model *m, size_t i, char *out, size_t n)
{
    const lnfmu_scene *s = m->s;
    const ln_data *d = m->d;
    if (i < (size_t)m->events_logged) {  /* rope_events.event_message's words, the kinds by the library's names */
        char t[40], label[512];
        const ln_int kind = d->event_kind[i], index = d->event_link[i];
        const int known = kind >= 0 && kind < s->n_event_kinds;
        python_repr(d->event_t[i], t, sizeof t);
        if (known && s->event_names_link[kind])  /* a rope's events name its link, the ground's a mass */
            link_label(s, index, label, sizeof label);
        else
            snprintf(label, sizeof label, "mass %lld (\"%s\")", (long long)(index + 1), mass_name(s, index));
        snprintf(out, n, "event at t=%s: %s of %s, impulse %.17g N s", t, known ? s->event_kind_names[kind] : "unknown",
                 label, d->event_impulse[i]);
        return 1;
    }
    if (i == (size_t)m->events_logged && m->events_lost > 0) {
        snprintf(out, n, "%lld more events of this step were not kept (the native core keeps %d per step): their "
                 "impulses are in Jrope and Jground, their times and kinds are not logged; take shorter communication "
                 "steps",
                 (long long)m->events_lost, LN_EVENT_LOG);
        return 1;
    }
    return 0;
}

/* ---- Booleans: estimate_error -------------------------------------------------------------------- */

static unsigned estimate_vr(const lnfmu_scene *s) { return (unsigned)s->n_real + 1u; }

int fmu_model_get_boolean(fmu_model *m, const unsigned *vr, size_t n, int *value, char *msg)
{
    const lnfmu_scene *s = m->s;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != estimate_vr(s))
            return fail(msg, FMU_ERROR, "value reference %u: no Boolean variable of this FMU has it (the only one is "
                        "estimate_error, %u)", vr[i], estimate_vr(s));
        value[i] = m->estimate;
    }
    return FMU_OK;
}

int fmu_model_set_boolean(fmu_model *m, const unsigned *vr, size_t n, const int *value, int initialized, char *msg)
{
    const lnfmu_scene *s = m->s;
    int chosen = m->estimate;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != estimate_vr(s))
            return fail(msg, FMU_ERROR, "value reference %u: no Boolean variable of this FMU has it (the only one is "
                        "estimate_error, %u); nothing set", vr[i], estimate_vr(s));
        const int x = value[i] != 0;
        if (initialized && x != m->estimate)
            return fail(msg, FMU_ERROR, "estimate_error is a fixed parameter and cannot be changed after "
                        "initialization (%s, current %s); nothing set", x ? "true" : "false",
                        m->estimate ? "true" : "false");
        chosen = x;
    }
    if (chosen != m->estimate) {
        m->estimate = chosen;
        m->dirty = 1;
    }
    return FMU_OK;
}

/* ---- state --------------------------------------------------------------------------------------- */

/* The links a data's rope state has (L with ropes, else none). */
static ln_int rope_state_links(const fmu_model *m) { return m->model.n_ropes ? m->s->L : 0; }

/* ln_data.slip_reference's entries: (n_contacts, 3) with friction (n_grips > 0), else none. */
static size_t slip_reference_doubles(const fmu_model *m) { return (size_t)(3 * m->model.n_grips / 2); }

/* Whether link l is one of friction's grips (the model's last n_grips links): in the mode while its contact sticks. */
static int is_grip_link(const fmu_model *m, ln_int l) { return l >= m->model.L - m->model.n_grips; }

/* A data's part of the state (the run's, then the companion's): t, h_next; planar, steps, rejected, n_rhs; X, U;
   body states; the driven anchors' clock (t0, start of the hold), their last jump (position, velocity, count), their
   held motion P, V, A and their impulse; with ropes, whether the mode was chosen, the mode (each link 1 where it is
   in the system, as a double: a friction grip's while its contact sticks) and each rope's impulse over the last
   step; with friction, each contact's slip reference (the direction of a sliding contact's slip at the last step's
   end: its velocity along it crossing zero is its stop in the next step). The ropes' event log is not state: the
   glue logs each step's events at its end, the log is empty between steps. */
static size_t data_state_doubles(const fmu_model *m)
{
    const lnfmu_scene *s = m->s;
    const ln_int ropes = rope_state_links(m);
    return (size_t)(2 + 4 + 6 * s->K + LN_RIGID_STATE * m->n_bodies + 5 + 12 * s->model->n_driven
                    + (ropes ? 1 + 2 * ropes : 0) + slip_reference_doubles(m));
}

/* start time; integrator, applied integrator, dirty, estimate, applied estimate, over goal, stepped; the estimate;
   the tension peaks and their times; values; applied; the run's data; the companion's data */
size_t fmu_model_state_size(const fmu_model *m)
{
    return sizeof(double) * ((size_t)(1 + 7 + 1 + 2 * m->s->L + 2 * m->s->n_real) + 2 * data_state_doubles(m));
}

static void put(unsigned char **p, const void *x, size_t n)
{
    if (n) memcpy(*p, x, n);
    *p += n;
}

static void put_int(unsigned char **p, ln_int x) { put(p, &x, sizeof x); }

static void get(const unsigned char **p, void *x, size_t n)
{
    if (n) memcpy(x, *p, n);
    *p += n;
}

static ln_int get_int(const unsigned char **p)
{
    ln_int x;
    get(p, &x, sizeof x);
    return x;
}

static void save_data(const fmu_model *m, const ln_data *d, unsigned char **p)
{
    const lnfmu_scene *s = m->s;
    const size_t n3 = (size_t)(3 * s->K) * sizeof(double), nd = (size_t)(3 * s->model->n_driven) * sizeof(double);
    put(p, &d->t, sizeof(double));
    put(p, &d->h_next, sizeof(double));
    put_int(p, d->planar);
    put_int(p, d->steps);
    put_int(p, d->rejected);
    put_int(p, d->n_rhs);
    put(p, d->X, n3);
    put(p, d->U, n3);
    if (m->n_bodies) {
        ln_rigid_get_state(&m->model, d, m->Ys);
        put(p, m->Ys, (size_t)(LN_RIGID_STATE * m->n_bodies) * sizeof(double));
    }
    put(p, &d->drive_t0, sizeof(double));
    put(p, &d->drive_hold_t, sizeof(double));
    put(p, &d->jump_position, sizeof(double));
    put(p, &d->jump_velocity, sizeof(double));
    put_int(p, d->jumps);
    put(p, d->drive_P, nd);
    put(p, d->drive_V, nd);
    put(p, d->drive_A, nd);
    put(p, d->impulse, nd);
    const ln_int ropes = rope_state_links(m);
    if (ropes) {
        put_int(p, d->mode_chosen);
        for (ln_int l = 0; l < ropes; l++) {
            const double active = d->link_active[l];
            put(p, &active, sizeof(double));
        }
        put(p, d->rope_impulse, (size_t)ropes * sizeof(double));
    }
    put(p, d->slip_reference, slip_reference_doubles(m) * sizeof(double));
}

void fmu_model_state_save(const fmu_model *m, unsigned char *buffer)
{
    const lnfmu_scene *s = m->s;
    unsigned char *p = buffer;
    const size_t nr = (size_t)s->n_real * sizeof(double);
    put(&p, &m->start_time, sizeof(double));
    put_int(&p, m->integrator);
    put_int(&p, m->applied_integrator);
    put_int(&p, m->dirty);
    put_int(&p, m->estimate);
    put_int(&p, m->applied_estimate);
    put_int(&p, m->over_goal);
    put_int(&p, m->stepped);
    put(&p, &m->error, sizeof(double));
    put(&p, m->peak, (size_t)(2 * s->L) * sizeof(double));
    put(&p, m->value, nr);
    put(&p, m->applied, nr);
    save_data(m, m->d, &p);
    save_data(m, m->dc, &p);
}

static int finite_all(const double *x, size_t n)
{
    double total = 0.0;
    for (size_t i = 0; i < n; i++) total += x[i] * 0.0;
    return isfinite(total);
}

/* A data's part of a state as read: arrays point into the restore's buffer. */
typedef struct data_state {
    double t, h_next;
    ln_int planar, steps, rejected, n_rhs;
    double *X, *U, *Y;
    double drive_t0, drive_hold_t, jump_position, jump_velocity;
    ln_int jumps;
    double *drive;  /* P, V, A, impulse: 3 n_driven each */
    ln_int mode_chosen;
    double *rope;   /* the mode (L, 0 or 1), then the ropes' impulses (L); with ropes only */
    double *slip_reference;  /* (n_contacts, 3); with friction only */
} data_state;

static void read_data(const fmu_model *m, const unsigned char **p, data_state *ds, double *arrays)
{
    const size_t n3 = (size_t)(3 * m->s->K), nb = (size_t)(LN_RIGID_STATE * m->n_bodies);
    const size_t nd = (size_t)(3 * m->s->model->n_driven);
    ds->X = arrays;
    ds->U = ds->X + n3;
    ds->Y = ds->U + n3;
    ds->drive = ds->Y + nb;
    ds->rope = ds->drive + 4 * nd;
    ds->slip_reference = ds->rope + 2 * (size_t)rope_state_links(m);
    get(p, &ds->t, sizeof(double));
    get(p, &ds->h_next, sizeof(double));
    ds->planar = get_int(p);
    ds->steps = get_int(p);
    ds->rejected = get_int(p);
    ds->n_rhs = get_int(p);
    get(p, ds->X, n3 * sizeof(double));
    get(p, ds->U, n3 * sizeof(double));
    get(p, ds->Y, nb * sizeof(double));
    get(p, &ds->drive_t0, sizeof(double));
    get(p, &ds->drive_hold_t, sizeof(double));
    get(p, &ds->jump_position, sizeof(double));
    get(p, &ds->jump_velocity, sizeof(double));
    ds->jumps = get_int(p);
    get(p, ds->drive, 4 * nd * sizeof(double));
    const size_t ropes = (size_t)rope_state_links(m);
    ds->mode_chosen = 0;
    if (ropes) {
        ds->mode_chosen = get_int(p);
        get(p, ds->rope, 2 * ropes * sizeof(double));
    }
    get(p, ds->slip_reference, slip_reference_doubles(m) * sizeof(double));
}

/* What a data's state says that is not possible, or NULL. */
static const char *data_problem(const fmu_model *m, const data_state *ds)
{
    const size_t n3 = (size_t)(3 * m->s->K), nb = (size_t)(LN_RIGID_STATE * m->n_bodies);
    const size_t nd = (size_t)(3 * m->s->model->n_driven);
    if ((ds->planar != 0 && ds->planar != 1) || ds->steps < 0 || ds->rejected < 0 || ds->n_rhs < 0)
        return "invalid internals";
    if (!isfinite(ds->t) || !(isfinite(ds->h_next) && ds->h_next >= 0.0)) return "a non-finite time or step";
    if (!finite_all(ds->X, 2 * n3) || !finite_all(ds->Y, nb)) return "a non-finite state";
    if (!(isfinite(ds->drive_t0) && isfinite(ds->drive_hold_t) && isfinite(ds->jump_position)
          && isfinite(ds->jump_velocity)) || ds->jumps < 0 || !finite_all(ds->drive, 4 * nd))
        return "a non-finite or invalid motion of the driven anchors";
    const ln_int ropes = rope_state_links(m);
    if (ropes) {
        if (ds->mode_chosen != 0 && ds->mode_chosen != 1) return "an invalid mode of the ropes";
        for (ln_int l = 0; l < ropes; l++)  /* 0 or 1; a rod always in the system, a grip while it sticks */
            if (!(ds->rope[l] == 1.0 || (ds->rope[l] == 0.0 && (is_rope_link(&m->model, l) || is_grip_link(m, l)))))
                return "an invalid mode of the ropes";
        if (!finite_all(ds->rope + ropes, (size_t)ropes)) return "a non-finite impulse of a rope";
    }
    if (!finite_all(ds->slip_reference, slip_reference_doubles(m))) return "a non-finite slip reference of friction";
    return NULL;
}

static void apply_data(fmu_model *m, ln_data *d, const data_state *ds)
{
    const size_t n3 = (size_t)(3 * m->s->K), nd = (size_t)(3 * m->s->model->n_driven);
    d->t = ds->t;
    d->h_next = ds->h_next;
    d->planar = (int)ds->planar && m->model.planar;
    d->steps = ds->steps;
    d->rejected = ds->rejected;
    d->n_rhs = ds->n_rhs;
    if (n3) {
        memcpy(d->X, ds->X, n3 * sizeof(double));
        memcpy(d->U, ds->U, n3 * sizeof(double));
    }
    d->drive_t0 = ds->drive_t0;
    d->drive_hold_t = ds->drive_hold_t;
    d->jump_position = ds->jump_position;
    d->jump_velocity = ds->jump_velocity;
    d->jumps = ds->jumps;
    if (nd) {
        memcpy(d->drive_P, ds->drive, nd * sizeof(double));
        memcpy(d->drive_V, ds->drive + nd, nd * sizeof(double));
        memcpy(d->drive_A, ds->drive + 2 * nd, nd * sizeof(double));
        memcpy(d->impulse, ds->drive + 3 * nd, nd * sizeof(double));
    }
    const ln_int ropes = rope_state_links(m);
    if (ropes) {  /* the mode and impulses; the log is empty between steps */
        d->mode_chosen = (int)ds->mode_chosen;
        for (ln_int l = 0; l < ropes; l++) d->link_active[l] = ds->rope[l] == 1.0;
        memcpy(d->rope_impulse, ds->rope + ropes, (size_t)ropes * sizeof(double));
        d->n_events = d->events_lost = d->events_this_step = 0;
    }
    if (slip_reference_doubles(m))
        memcpy(d->slip_reference, ds->slip_reference, slip_reference_doubles(m) * sizeof(double));
}

int fmu_model_state_restore(fmu_model *m, const unsigned char *buffer, size_t size, char *msg)
{
    const lnfmu_scene *s = m->s;
    if (size != fmu_model_state_size(m)) return fail(msg, FMU_ERROR, "a state of the wrong size");
    const size_t n_real = (size_t)s->n_real, per_data = data_state_doubles(m), n_peak = (size_t)(2 * s->L);
    double *value = malloc((2 * n_real + 2 * per_data + n_peak + 1) * sizeof(double));
    if (!value) return fail(msg, FMU_ERROR, "out of memory");
    double *applied = value + n_real, *arrays = applied + n_real, *peak = arrays + 2 * per_data;
    const unsigned char *p = buffer;
    double start_time, error;
    get(&p, &start_time, sizeof(double));
    const ln_int integrator = get_int(&p), applied_integrator = get_int(&p), dirty = get_int(&p);
    const ln_int estimate = get_int(&p), applied_estimate = get_int(&p), over_goal = get_int(&p);
    const ln_int stepped = get_int(&p);
    get(&p, &error, sizeof(double));
    get(&p, peak, n_peak * sizeof(double));
    get(&p, value, n_real * sizeof(double));
    get(&p, applied, n_real * sizeof(double));
    data_state run, companion;
    read_data(m, &p, &run, arrays);
    read_data(m, &p, &companion, arrays + per_data);

    /* what the state says must be possible for this FMU */
    const char *problem = NULL;
    if (integrator < 0 || integrator >= s->n_methods || applied_integrator < 0 || applied_integrator >= s->n_methods)
        problem = "an integrator index out of range";
    else if ((dirty != 0 && dirty != 1) || (estimate != 0 && estimate != 1) || (applied_estimate != 0
             && applied_estimate != 1) || (over_goal != 0 && over_goal != 1) || (stepped != 0 && stepped != 1)
             || !(error >= 0.0))
        problem = "invalid internals";
    else if (!isfinite(start_time))
        problem = "a non-finite time or step";
    if (!problem) problem = data_problem(m, &run);
    if (!problem) problem = data_problem(m, &companion);
    for (size_t vr = 0; vr < n_real && !problem; vr++) {
        const int kind = s->variables[vr].kind;
        char why[256];
        if (is_input(kind) && !(isfinite(value[vr]) && isfinite(applied[vr]))) problem = "a non-finite input";
        if (is_parameter(kind) && (parameter_rule(s, kind, value[vr], why, sizeof why)
                                   || parameter_rule(s, kind, applied[vr], why, sizeof why)))
            problem = "a parameter out of range";
    }
    if (problem) {
        free(value);
        return fail(msg, FMU_ERROR, "refused: %s", problem);
    }

    /* the model of the state's parameters (rebuilt only if they are not the current ones) */
    int same = applied_integrator == m->applied_integrator;
    for (size_t vr = 0; vr < n_real && same; vr++)
        if (is_parameter(s->variables[vr].kind) && applied[vr] != m->applied[vr]) same = 0;
    if (!same) {
        const int result = build(m, applied, applied_integrator, msg);
        if (result != FMU_OK) {
            char ignored[FMU_MESSAGE];
            build(m, m->applied, m->applied_integrator, ignored);
            free(value);
            return result;
        }
        memcpy(m->applied, applied, n_real * sizeof(double));
        m->applied_integrator = applied_integrator;
    }
    if (m->n_bodies && (ln_rigid_set_state(&m->model, m->d, run.Y) != LN_OK
                        || ln_rigid_set_state(&m->model, m->dc, companion.Y) != LN_OK)) {
        free(value);
        return fail(msg, FMU_ERROR, "refused: the rigid-body state is not valid (zero quaternion)");
    }
    memcpy(m->value, value, n_real * sizeof(double));
    m->integrator = integrator;
    m->dirty = (int)dirty;
    m->estimate = (int)estimate;
    m->applied_estimate = (int)applied_estimate;
    m->over_goal = (int)over_goal;
    m->error = error;
    m->stepped = (int)stepped;
    if (n_peak) memcpy(m->peak, peak, n_peak * sizeof(double));
    m->start_time = start_time;
    apply_data(m, m->d, &run);
    apply_data(m, m->dc, &companion);
    m->events_logged = m->events_lost = 0;  /* logged with the step that made them */
    load_inputs(m);
    clear_anchor_marks(m);  /* which inputs were set is not in the state: a jump from it is said as one of P */
    m->outputs_stale = m->interface_stale = 1;
    free(value);
    return FMU_OK;
}
