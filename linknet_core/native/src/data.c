/* The data (mutable state, internals, scratch) and the whole-interval advance: one call per output or
   communication interval runs every step, assembly, factorisation and projection in C, all or nothing. */
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "drive.h"
#include "ldl.h"
#include "linknet.h"
#include "ln_math.h"
#include "minnorm.h"
#include "rigid.h"
#include "tension_peaks.h"

#define FN(name) name##_2d
#include "stages.h"
#undef FN
#define FN(name) name##_3d
#include "stages.h"
#undef FN

/* ln_data's fields as its list (ln_data_fields.h) says each lives; a macro a field's kind does not use expands to
   nothing. The ARRAY counts read the model as `m` and the data as `s`. */
#define IGNORE_FIELD(type, name)
#define IGNORE_ARRAY(type, name, count)
#define IGNORE_OWNED(type, name, release)

/* every ARRAY, at least one entry each (a pointer that is not NULL), zeroed; 0 when out of memory */
#define ALLOCATE_ARRAY(type, name, count) \
    ok = ok && (d->name = calloc((size_t)((count) > 0 ? (count) : 1), sizeof(type))) != NULL;
static int allocate_arrays(const ln_model *m, ln_data *d)
{
    const ln_data *s = d;
    int ok = 1;
    LN_DATA_FIELDS(IGNORE_FIELD, IGNORE_FIELD, ALLOCATE_ARRAY, IGNORE_OWNED, IGNORE_FIELD)
    (void)s;
    return ok;
}

/* every SCALAR and ARRAY entry back to zero and every BORROWED pointer to NULL */
#define ZERO_SCALAR(type, name) d->name = (type)0;
#define ZERO_ARRAY(type, name, count) \
    if ((count) > 0) memset(d->name, 0, (size_t)(count) * sizeof(type));
#define FORGET_BORROWED(type, name) d->name = NULL;
static void zero_fields(const ln_model *m, ln_data *d)
{
    const ln_data *s = d;
    LN_DATA_FIELDS(ZERO_SCALAR, IGNORE_FIELD, ZERO_ARRAY, IGNORE_OWNED, FORGET_BORROWED)
    (void)s;
}

#define FREE_ARRAY(type, name, count) free(d->name);
#define RELEASE_OWNED(type, name, release) release(d->name);
void ln_data_free(ln_data *d)
{
    if (!d) return;
    LN_DATA_FIELDS(IGNORE_FIELD, IGNORE_FIELD, FREE_ARRAY, RELEASE_OWNED, IGNORE_FIELD)
    free(d);
}

/* What a new data holds beyond zeros (ln_data_new and ln_data_reset). */
static void initial_values(const ln_model *m, ln_data *d)
{
    d->planar = m->planar;
    d->fail_link = -1;
    d->drive_hold_t = d->drive_t0;  /* the scene's time origin is the data's setting, kept */
    /* input-driven anchors rest at their scene position until an input arrives: the first row of their
       piece table (drive.c) holds it */
    for (ln_int a = 0; a < m->n_driven; a++)
        for (int e = 0; e < 3; e++) d->drive_P[3 * a + e] = m->piece[14 * m->motion_pieces[a] + 2 + 4 * e];
}

ln_data *ln_data_new(const ln_model *m, ln_int n_stages)
{
    ln_data *d = calloc(1, sizeof *d);
    if (!d) return NULL;
    d->n_stages_allocated = n_stages > 0 ? n_stages : 0;  /* before the arrays: the stages' arrays count on it */
    int ok = allocate_arrays(m, d);
    if (ok && m->solver == LN_SOLVER_LDL) ok = (d->ldl = ln_ldl_numeric_new(m->ldl)) != NULL;
    if (ok && m->rigid) ok = (d->rigid = ln_rigid_data_new(m, n_stages)) != NULL;
    if (!ok) {
        ln_data_free(d);
        return NULL;
    }
    initial_values(m, d);
    return d;
}

void ln_data_reset(const ln_model *m, ln_data *d)
{
    zero_fields(m, d);
    initial_values(m, d);
}

/* The most steps one advance counts: beyond 2^53 the ratio span / dt is no longer a whole number in double (and
   no run takes that many steps: 2^53 of 1 ns each are 104 days of computing). */
LN_API const ln_int ln_max_step_count = (ln_int)1 << 53;

ln_int ln_fixed_step_count(double span, double dt)
{
    const double ratio = span / dt, nearest = ln_round(ratio);
    /* more than the limit, or not a number (dt = 0, an infinite span): more than any advance may take. Converted
       to ln_int such a ratio would be undefined (INT64_MIN on x86-64: a run of 0 steps reported as done) */
    if (!(ratio <= (double)ln_max_step_count)) return ln_max_step_count + 1;
    /* a whole number of steps up to round-off in t (which grows with t) is that number, not one more */
    const double n = fabs(ratio - nearest) <= 1e-9 * ln_fmax(ratio, 1.0) ? nearest : ln_ceil(ratio);
    return n < 1.0 ? 1 : (ln_int)n;
}

int ln_step_count_problem(double t, double t_target, double dt, ln_int max_steps, char *out, size_t n)
{
    if (max_steps > ln_max_step_count) max_steps = ln_max_step_count;
    const double span = t_target - t;
    const ln_int steps = ln_fixed_step_count(span, dt);
    if (steps <= max_steps) return 0;
    char count[64];
    if (steps <= ln_max_step_count)
        snprintf(count, sizeof count, "%lld", (long long)steps);
    else if (isfinite(span / dt))
        snprintf(count, sizeof count, "about %.3g", span / dt);
    else
        snprintf(count, sizeof count, "more than %.3g", DBL_MAX);
    snprintf(out, n, "reaching t = %g from t = %g (a span of %g s) takes %s steps of dt = %g: more than %lld steps, "
             "the limit of one advance; advance over intervals of at most %g s, or use a longer dt", t_target, t, span,
             count, dt, (long long)max_steps, (double)max_steps * dt);
    return 1;
}

int ln_base_forces(const ln_model *m, const ln_data *d, double *F_base)
{
    double total = 0.0;
    for (ln_int k = 0; k < m->K; k++)
        for (int e = 0; e < 3; e++) {
            const ln_int i = 3 * k + e;
            F_base[i] = m->is_fixed[k] ? 0.0 : m->F_scene[i] + d->F_input[i];
            total += F_base[i];
        }
    return isfinite(total);
}

int ln_evaluate(const ln_model *m, ln_data *d, const double *X, const double *U)
{
    if (!ln_base_forces(m, d, d->F_base)) return LN_NON_FINITE;
    if (m->n_driven) {  /* the driven anchors where they are at d->t, with their accelerations in B (26) */
        const size_t bytes = (size_t)(3 * m->K) * sizeof(double);
        memcpy(d->Xs, X, bytes);
        memcpy(d->Us, U, bytes);
        const int status = ln_drive_rows(m, d, d->t, d->Xs, d->Us, d->F_base, 3);
        if (status != LN_OK) return status;
        X = d->Xs;
        U = d->Us;
    }
    d->n_rhs++;
    const int status = m->n_ropes ? ln_rope_evaluate(m, d, X, U) : ln_accelerations_3d(m, d, X, U, d->F_base, d->acc,
                                                                                         d->T, 1);
    /* the link forces on the anchors, gathered in the rows of a (K,3) scratch (only anchors' rows used) */
    double *on_mass = d->Uh;
    for (ln_int i = 0; i < m->n_fixed; i++)
        for (int e = 0; e < 3; e++) on_mass[3 * m->fixed_idx[i] + e] = 0.0;
    for (ln_int l = 0; l < m->L; l++) {
        const ln_int a = m->k1[l], b = m->k2[l];
        if (!m->is_fixed[a] && !m->is_fixed[b]) continue;
        for (int e = 0; e < 3; e++) {
            const double f = d->T[l] * (X[3 * b + e] - X[3 * a + e]) * m->inv_R[l];  /* T_l E_l (8) */
            if (m->is_fixed[a]) on_mass[3 * a + e] += f;
            if (m->is_fixed[b]) on_mass[3 * b + e] -= f;
        }
    }
    for (ln_int i = 0; i < m->n_fixed; i++)
        for (int e = 0; e < 3; e++) d->reaction[3 * i + e] = on_mass[3 * m->fixed_idx[i] + e];
    return status;
}

int ln_evaluate_repeated(const ln_model *m, ln_data *d, int dim, const double *X, const double *U, ln_int n)
{
    if (!ln_base_forces(m, d, d->F_base)) return LN_NON_FINITE;
    const double *F_base = d->F_base;
    if (dim == 2) {  /* X, U are in the plane's coordinates: the base force goes there too */
        const double *P = m->plane_P;
        for (ln_int k = 0; k < m->K; k++)
            for (int j = 0; j < 2; j++)
                d->Fp[2 * k + j] = P[j] * d->F_base[3 * k] + P[2 + j] * d->F_base[3 * k + 1] + P[4 + j] * d->F_base[3 * k + 2];
        F_base = d->Fp;
    }
    int status = LN_OK;
    for (ln_int i = 0; i < n && status == LN_OK; i++)
        status = dim == 2 ? ln_accelerations_2d(m, d, X, U, F_base, d->acc, d->T, 1)
                          : ln_accelerations_3d(m, d, X, U, F_base, d->acc, d->T, 1);
    d->n_rhs += n;
    return status;
}

/* The state and base forces in the plane's coordinates: X = P^T (X3 - o), U = P^T U3, F = P^T F3. 0 when a
   position, velocity or force on a free mass has a component along the normal beyond round-off. */
static int enter_plane(const ln_model *m, ln_data *d)
{
    const double *P = m->plane_P, *o = m->plane_o, *n = m->plane_n;
    const double c = n[0] * o[0] + n[1] * o[1] + n[2] * o[2], tol = m->plane_tol;
    for (ln_int k = 0; k < m->K; k++) {
        const double *X = d->X + 3 * k, *U = d->U + 3 * k, *F = d->F_base + 3 * k;
        double x_off = -c, x_size = fabs(c) + m->plane_length, u_off = 0.0, u_size = 0.0, f_off = 0.0, f_size = 0.0;
        for (int e = 0; e < 3; e++) {
            x_off += n[e] * X[e];
            x_size += fabs(X[e]);
            u_off += n[e] * U[e];
            u_size += fabs(U[e]);
            f_off += n[e] * F[e];
            f_size += fabs(F[e]);
        }
        if (!(fabs(x_off) <= tol * x_size && fabs(u_off) <= tol * u_size && fabs(f_off) <= tol * f_size)) return 0;
        for (int j = 0; j < 2; j++) {
            double x = 0.0, u = 0.0, f = 0.0;
            for (int e = 0; e < 3; e++) {
                x += P[2 * e + j] * (X[e] - o[e]);
                u += P[2 * e + j] * U[e];
                f += P[2 * e + j] * F[e];
            }
            d->Xp[2 * k + j] = x;
            d->Up[2 * k + j] = u;
            d->Fp[2 * k + j] = f;
        }
    }
    return 1;
}

/* Back to 3-D: X3 = o + P X, U3 = P U; anchors keep their coordinates exactly (in a tilted plane the round
   trip would move them by round-off). */
static void leave_plane(const ln_model *m, ln_data *d)
{
    const double *P = m->plane_P, *o = m->plane_o;
    for (ln_int k = 0; k < m->K; k++) {
        if (m->is_fixed[k]) continue;
        for (int e = 0; e < 3; e++) {
            d->X[3 * k + e] = o[e] + P[2 * e] * d->Xp[2 * k] + P[2 * e + 1] * d->Xp[2 * k + 1];
            d->U[3 * k + e] = P[2 * e] * d->Up[2 * k] + P[2 * e + 1] * d->Up[2 * k + 1];
        }
    }
}

static int run_interval(const ln_model *m_scene, const ln_method *meth, ln_data *d, double t_target, ln_int max_steps,
                        ln_int *steps)
{
    /* ropes: the stages run on the mode's model, whose 1/R_l is 0 on the slack ropes (stages/ropes.c) */
    ln_model mode;
    const ln_model *m = m_scene;
    if (m_scene->n_ropes) {
        mode = *m_scene;
        mode.inv_R = d->mode_inv_R;
        m = &mode;
    }
    const double span = t_target - d->t;
    int planar = d->planar && enter_plane(m, d);
    d->planar = planar;  /* once the state or an input has left the plane, 3-D from then on */
    double *X = planar ? d->Xp : d->X, *U = planar ? d->Up : d->U;
    const double *F_base = planar ? d->Fp : d->F_base;
    int status;
    if (meth->kind == LN_COMPOSITION) {
        const ln_int n = ln_fixed_step_count(span, meth->dt);
        if (n > max_steps) return LN_TOO_MANY_STEPS;
        status = planar ? ln_rattle_steps_2d(m, meth, d, X, U, F_base, n, d->t, t_target, steps)
                        : ln_rattle_steps_3d(m, meth, d, X, U, F_base, n, d->t, t_target, steps);
    } else {
        double t = d->t;
        status = planar ? ln_rk_steps_2d(m, meth, d, X, U, F_base, &t, t_target, max_steps, steps)
                        : ln_rk_steps_3d(m, meth, d, X, U, F_base, &t, t_target, max_steps, steps);
    }
    if (planar) leave_plane(m, d);
    return status;
}

int ln_jump_anchors(const ln_model *m, const ln_method *meth, ln_data *d)
{
    if (!ln_base_forces(m, d, d->F_base)) return LN_NON_FINITE;
    return m->n_driven ? ln_drive_jump(m, meth, d) : LN_OK;
}

int ln_advance(const ln_model *m, const ln_method *meth, ln_data *d, double t_target, ln_int max_steps)
{
    const ln_int n3 = 3 * m->K;
    d->status = LN_OK;
    d->fail_link = -1;
    d->fail_t = d->t;
    if (!(isfinite(t_target) && t_target > d->t) || max_steps < 1) return d->status = LN_BAD_ARGUMENT;
    if (max_steps > ln_max_step_count) max_steps = ln_max_step_count;  /* no count beyond it is a count */
    if (!ln_base_forces(m, d, d->F_base)) return d->status = LN_NON_FINITE;
    if (meth->kind == LN_STATIC) {  /* 0 degrees of freedom: nothing moves */
        d->t = t_target;
        d->last_steps = 0;
        return LN_OK;
    }
    /* all or nothing: what a failed interval changed is put back */
    const double h_next = d->h_next;
    const int planar = d->planar;
    const ln_int rejected = d->rejected, n_rhs = d->n_rhs, split_steps = d->split_steps, finest_split = d->finest_split;
    const ln_int jumps = d->jumps;
    /* ropes: the mode, the log and the impulses are part of what is put back */
    const int mode_chosen = d->mode_chosen;
    const ln_int n_events = d->n_events, events_lost = d->events_lost, events_this_step = d->events_this_step;
    if (m->n_ropes) {
        memcpy(d->active_start, d->link_active, (size_t)m->L);
        memcpy(d->impulse_start, d->rope_impulse, (size_t)m->L * sizeof(double));
        memset(d->rope_impulse, 0, (size_t)m->L * sizeof(double));
        if (m->n_grips)
            memcpy(d->slip_reference_start, d->slip_reference, (size_t)(3 * m->n_grips / 2) * sizeof(double));
    }
    memcpy(d->X_start, d->X, (size_t)n3 * sizeof(double));
    memcpy(d->U_start, d->U, (size_t)n3 * sizeof(double));
    ln_int steps = 0;
    int status = m->n_driven ? ln_drive_jump(m, meth, d) : LN_OK;
    if (status == LN_OK)
        status = m->rigid ? ln_rigid_advance(m, meth, d, t_target, max_steps, &steps)
                          : run_interval(m, meth, d, t_target, max_steps, &steps);
    if (status == LN_OK) {
        double total = 0.0;
        for (ln_int i = 0; i < n3; i++) total += d->X[i] * d->X[i] + d->U[i] * d->U[i];
        if (!isfinite(total)) status = LN_NON_FINITE;
    }
    if (status != LN_OK) {
        memcpy(d->X, d->X_start, (size_t)n3 * sizeof(double));
        memcpy(d->U, d->U_start, (size_t)n3 * sizeof(double));
        d->h_next = h_next;
        d->planar = planar;
        d->rejected = rejected;
        d->n_rhs = n_rhs;
        d->split_steps = split_steps;
        d->finest_split = finest_split;
        d->jumps = jumps;
        if (m->n_ropes) {
            memcpy(d->link_active, d->active_start, (size_t)m->L);
            memcpy(d->rope_impulse, d->impulse_start, (size_t)m->L * sizeof(double));
            if (m->n_grips)
                memcpy(d->slip_reference, d->slip_reference_start, (size_t)(3 * m->n_grips / 2) * sizeof(double));
            d->mode_chosen = mode_chosen;
            d->n_events = n_events;
            d->events_lost = events_lost;
            d->events_this_step = events_this_step;
        }
        if (m->rigid) ln_rigid_restore(m, d);
        return d->status = status;
    }
    d->t = t_target;
    d->steps += steps;
    d->last_steps = steps;
    return LN_OK;
}

int ln_sample(const ln_model *m, const ln_method *meth, ln_data *d, const double *times, ln_int n, int advance_first,
              ln_int max_steps, double *X_out, double *U_out, double *T_out, double *T_peak_out,
              double *T_peak_time_out, const ln_energy_terms *energy, double *diagnostics_out,
              ln_int diagnostics_stride, ln_int *written)
{
    const size_t state_bytes = (size_t)(3 * m->K) * sizeof(double), T_bytes = (size_t)m->L * sizeof(double);
    *written = 0;
    for (ln_int i = 0; i < n; i++) {
        int status;
        const int advanced = i > 0 || advance_first;
        if (advanced && (status = ln_advance(m, meth, d, times[i], max_steps)) != LN_OK) return status;
        if ((status = ln_evaluate(m, d, d->X, d->U)) != LN_OK) return status;
        memcpy(X_out + 3 * m->K * i, d->X, state_bytes);
        memcpy(U_out + 3 * m->K * i, d->U, state_bytes);
        if (T_bytes) memcpy(T_out + m->L * i, d->T, T_bytes);
        if (T_peak_out) ln_tension_peaks(m, d, advanced, T_peak_out + m->L * i, T_peak_time_out + m->L * i);
        if (diagnostics_out) {
            double values[4];
            ln_sample_diagnostics(m, energy, d->X, d->U, values);
            for (int j = 0; j < 4; j++) diagnostics_out[j * diagnostics_stride + i] = values[j];
        }
        *written = i + 1;
    }
    return LN_OK;
}
