/* Free rigid bodies: whole-interval advances of the body states (rigid.h).
 *
 * Fixed-step methods. One base step of size h (the role RATTLE plays for point masses: 2nd order,
 * symplectic and time-reversible for conservative forces):
 *     half kick   v += h/2 f/m,   Pi += h/2 R^T tau
 *     drift       c += h v
 *     rotate      the free-rotation flow over h, exact or split
 *     half kick   with the forces at the new positions (implicit in the new velocities when the forces
 *                 depend on them: drag, dampers; fixed-point iteration)
 * Explicit first and implicit second half kick are each other's adjoints, so the step is symmetric and
 * second order, and the compositions (method->gammas) keep their orders.
 *
 * Free rotation, T = Pi_1^2/(2 I_1) + Pi_2^2/(2 I_2) + Pi_3^2/(2 I_3):
 *   spherical top:  exact, one rotation about Pi by h |Pi| / I;
 *   symmetric top:  exact, T = |Pi|^2/(2 I_1) + (1/I_3 - 1/I_1) Pi_3^2/2 is two commuting flows, a rotation
 *                   about Pi by h |Pi|/I_1 and one about body axis 3 by h (1/I_3 - 1/I_1) Pi_3;
 *   asymmetric top: the symmetric splitting of Dullweber, Leimkuhler and McLachlan (J. Chem. Phys. 107,
 *                   5840, 1997) R1(h/2) R2(h/2) R3(h) R2(h/2) R1(h/2), R_i the exact flow of Pi_i^2/(2 I_i).
 * Every sub-flow rotates R on the right and Pi by the inverse rotation, so the space angular momentum R Pi
 * is kept to round-off when there is no torque, and |Pi| exactly.
 *
 * Adaptive methods: the method's embedded Runge-Kutta pair on the Newton-Euler equations of the body state,
 *     dc/dt = v,  dv/dt = f / m,  dq/dt = q (x) (0, w) / 2,  dPi/dt = Pi x w + R^T tau,   w = Pi / I,
 * with the map Y -> masses through the rotation of q / |q| (a stage need not keep |q|) and q renormalised
 * after every accepted step (the analogue of the point-mass path's projections). The error is measured on
 * the masses, as the point-mass path measures it: from their velocities and accelerations at every stage
 * (the tangent of Y -> (X, U) applied to dY/dt), in the same norm, so rtol means the same position accuracy
 * on both paths. A norm on the body state itself would mix units (m, m/s, 1, kg m^2/s) and give every body
 * another accuracy for the same rtol.
 */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "linknet.h"
#include "ln_math.h"
#include "rigid.h"

#define FN(name) name##_3d  /* the rigid path is 3-D: the point-mass stages it shares are the 3-D ones */
#include "stages.h"
#undef FN

#define NY LN_RIGID_STATE
#define IMPLICIT_KICK_ITERATIONS 100

/* columns of a body-state row */
enum { COL_C = 0, COL_V = 3, COL_Q = 6, COL_PI = 10 };

static double *doubles(ln_int n) { return calloc((size_t)(n > 0 ? n : 1), sizeof(double)); }

/* the larger of a and b, a when b is not larger (a NaN b is ignored, as Python's max(a, b) does) */
static inline double larger(double a, double b) { return b > a ? b : a; }

void ln_rigid_data_free(struct ln_rigid_data *r)
{
    if (!r) return;
#define FREE_ARRAY(name, count) free(r->name);
    LN_RIGID_DATA_ARRAYS(FREE_ARRAY)
#undef FREE_ARRAY
    free(r);
}

struct ln_rigid_data *ln_rigid_data_new(const ln_model *m, ln_int n_stages)
{
    if (!m->rigid) return NULL;
    struct ln_rigid_data *r = calloc(1, sizeof *r);
    if (!r) return NULL;
    const ln_int B = m->rigid->n_bodies;
    if (n_stages < 0) n_stages = 0;
    r->n_bodies = B;
    int ok = 1;
#define NEW_ARRAY(name, count) ok = ok && (r->name = doubles(count)) != NULL;
    LN_RIGID_DATA_ARRAYS(NEW_ARRAY)
#undef NEW_ARRAY
    if (!ok) {
        ln_rigid_data_free(r);
        return NULL;
    }
    for (ln_int b = 0; b < B; b++) r->Y[NY * b + COL_Q] = 1.0;  /* a valid attitude until the state is set */
    return r;
}

/* F_k of (9) at (X, U): the base forces themselves when no force element depends on the state. */
static inline const double *forces(const ln_model *m, ln_data *d, const double *X, const double *U,
                                   const double *F_base)
{
    if (m->n_elements == 0) return F_base;
    ln_scene_forces_3d(m, X, U, F_base, d->F);
    return d->F;
}

/* Resultant f and moment tau (about c, space frame) of the forces F on each body; c is column COL_C of the
   body states Y. */
static void loads(const ln_model *m, const double *Y, const double *X, const double *F, double *f, double *tau)
{
    const struct ln_rigid_model *rm = m->rigid;
    for (ln_int i = 0; i < 3 * rm->n_bodies; i++) f[i] = tau[i] = 0.0;
    for (ln_int k = 0; k < m->K; k++) {
        const ln_int b = rm->body_of[k];
        if (b < 0) continue;
        const double *x = X + 3 * k, *Fk = F + 3 * k, *c = Y + NY * b + COL_C;
        const double p0 = x[0] - c[0], p1 = x[1] - c[1], p2 = x[2] - c[2];
        f[3 * b] += Fk[0];
        f[3 * b + 1] += Fk[1];
        f[3 * b + 2] += Fk[2];
        tau[3 * b] += p1 * Fk[2] - p2 * Fk[1];
        tau[3 * b + 1] += p2 * Fk[0] - p0 * Fk[2];
        tau[3 * b + 2] += p0 * Fk[1] - p1 * Fk[0];
    }
}

/* ---- fixed-step compositions ----------------------------------------------------------------------- */

/* q <- q (x) (cos(angle/2), sin(angle/2) u) for a unit body axis u: R <- R Rot(u, angle). */
static void rotate_right(double *q, double u0, double u1, double u2, double angle)
{
    const double ch = ln_cos(0.5 * angle), sh = ln_sin(0.5 * angle);
    const double p1 = sh * u0, p2 = sh * u1, p3 = sh * u2;
    const double w = q[0], x = q[1], y = q[2], z = q[3];
    q[0] = w * ch - x * p1 - y * p2 - z * p3;
    q[1] = w * p1 + x * ch + y * p3 - z * p2;
    q[2] = w * p2 + y * ch + z * p1 - x * p3;
    q[3] = w * p3 + z * ch + x * p2 - y * p1;
}

/* Exact flow of Pi_i^2/(2 I_i) (angle = t Pi_i / I_i): R <- R Rot_i(angle), Pi <- Rot_i(angle)^T Pi. */
static void axis_flow(double *q, double *Pi, int i, double angle)
{
    rotate_right(q, i == 0 ? 1.0 : 0.0, i == 1 ? 1.0 : 0.0, i == 2 ? 1.0 : 0.0, angle);
    const int j = (i + 1) % 3, k = (i + 2) % 3;
    const double c = ln_cos(angle), s = ln_sin(angle), pj = Pi[j], pk = Pi[k];
    Pi[j] = c * pj + s * pk;
    Pi[k] = -s * pj + c * pk;
}

/* Exact flow of |Pi|^2/(2 I): a rotation about Pi (fixed in both frames) by t |Pi| / I. */
static void about_momentum(double *q, const double *Pi, double t, double inertia)
{
    const double p = ln_sqrt(Pi[0] * Pi[0] + Pi[1] * Pi[1] + Pi[2] * Pi[2]);
    if (p > 0.0) rotate_right(q, Pi[0] / p, Pi[1] / p, Pi[2] / p, t * p / inertia);
}

/* Torque-free rotation of every body over time t, q renormalised. */
static void free_rotation(const struct ln_rigid_model *rm, double *Y, double t)
{
    for (ln_int b = 0; b < rm->n_bodies; b++) {
        double *q = Y + NY * b + COL_Q, *Pi = Y + NY * b + COL_PI;
        const double *I = rm->inertia + 3 * b;
        if (rm->kind[b] == LN_SPHERICAL_TOP) {
            about_momentum(q, Pi, t, I[0]);
        } else if (rm->kind[b] == LN_SYMMETRIC_TOP) {
            about_momentum(q, Pi, t, I[0]);
            axis_flow(q, Pi, 2, t * (1.0 / I[2] - 1.0 / I[0]) * Pi[2]);
        } else {
            axis_flow(q, Pi, 0, 0.5 * t * Pi[0] / I[0]);
            axis_flow(q, Pi, 1, 0.5 * t * Pi[1] / I[1]);
            axis_flow(q, Pi, 2, t * Pi[2] / I[2]);
            axis_flow(q, Pi, 1, 0.5 * t * Pi[1] / I[1]);
            axis_flow(q, Pi, 0, 0.5 * t * Pi[0] / I[0]);
        }
        const double norm = ln_sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
        for (int e = 0; e < 4; e++) q[e] /= norm;
    }
}

/* R of each body's unit quaternion q = (w, x, y, z). */
static void rotation_matrices(ln_int B, const double *Y, double *R)
{
    for (ln_int b = 0; b < B; b++) {
        const double *q = Y + NY * b + COL_Q;
        const double w = q[0], x = q[1], y = q[2], z = q[3];
        double *Rb = R + 9 * b;
        Rb[0] = 1.0 - 2.0 * (y * y + z * z);
        Rb[1] = 2.0 * (x * y - w * z);
        Rb[2] = 2.0 * (x * z + w * y);
        Rb[3] = 2.0 * (x * y + w * z);
        Rb[4] = 1.0 - 2.0 * (x * x + z * z);
        Rb[5] = 2.0 * (y * z - w * x);
        Rb[6] = 2.0 * (x * z - w * y);
        Rb[7] = 2.0 * (y * z + w * x);
        Rb[8] = 1.0 - 2.0 * (x * x + y * y);
    }
}

/* X_k = c + R r_k and U_k = v + w x (R r_k), w = R I^-1 Pi, for every mass of a body (the others keep
   theirs); R of the unit quaternions into rd->R. */
static void mass_states(const ln_model *m, struct ln_rigid_data *rd, const double *Y, double *X, double *U)
{
    const struct ln_rigid_model *rm = m->rigid;
    const ln_int B = rm->n_bodies;
    double *R = rd->R, *w = rd->w;
    rotation_matrices(B, Y, R);
    for (ln_int b = 0; b < B; b++) {
        const double *Pi = Y + NY * b + COL_PI, *I = rm->inertia + 3 * b, *Rb = R + 9 * b;
        const double wb0 = Pi[0] / I[0], wb1 = Pi[1] / I[1], wb2 = Pi[2] / I[2];
        for (int e = 0; e < 3; e++) w[3 * b + e] = Rb[3 * e] * wb0 + Rb[3 * e + 1] * wb1 + Rb[3 * e + 2] * wb2;
    }
    for (ln_int k = 0; k < m->K; k++) {
        const ln_int b = rm->body_of[k];
        if (b < 0) continue;
        const double *Rb = R + 9 * b, *r = rm->r + 3 * k, *c = Y + NY * b + COL_C, *v = Y + NY * b + COL_V;
        const double *wb = w + 3 * b;
        const double p0 = Rb[0] * r[0] + Rb[1] * r[1] + Rb[2] * r[2];
        const double p1 = Rb[3] * r[0] + Rb[4] * r[1] + Rb[5] * r[2];
        const double p2 = Rb[6] * r[0] + Rb[7] * r[1] + Rb[8] * r[2];
        double *x = X + 3 * k, *u = U + 3 * k;
        x[0] = c[0] + p0;
        x[1] = c[1] + p1;
        x[2] = c[2] + p2;
        u[0] = v[0] + wb[1] * p2 - wb[2] * p1;
        u[1] = v[1] + wb[2] * p0 - wb[0] * p2;
        u[2] = v[2] + wb[0] * p1 - wb[1] * p0;
    }
}

/* v += hk f / m and Pi += hk R^T tau (the torque taken into the body frame at the current attitude). */
static void kick(const struct ln_rigid_model *rm, struct ln_rigid_data *rd, double *Y, double hk)
{
    for (ln_int b = 0; b < rm->n_bodies; b++) {
        double *v = Y + NY * b + COL_V, *Pi = Y + NY * b + COL_PI;
        const double *Rb = rd->R + 9 * b, *f = rd->f + 3 * b, *tau = rd->tau + 3 * b;
        for (int e = 0; e < 3; e++) {
            v[e] += hk * f[e] / rm->body_mass[b];
            Pi[e] += hk * (Rb[e] * tau[0] + Rb[3 + e] * tau[1] + Rb[6 + e] * tau[2]);
        }
    }
}

/* The masses' states, forces and loads at the body states Y. */
static void evaluate_loads(const ln_model *m, ln_data *d, const double *Y, const double *F_base)
{
    struct ln_rigid_data *rd = d->rigid;
    mass_states(m, rd, Y, d->X, d->U);
    loads(m, Y, d->X, forces(m, d, d->X, d->U, F_base), rd->f, rd->tau);
}

/* (v, Pi) <- (v, Pi) + hk (f, R^T tau) with f, tau at the new velocities: fixed-point iteration until the
   iterates stop changing beyond round-off. 0 if it does not converge (damping too stiff for the step). */
static int implicit_kick(const ln_model *m, ln_data *d, double *Y, const double *F_base, double hk)
{
    const struct ln_rigid_model *rm = m->rigid;
    struct ln_rigid_data *rd = d->rigid;
    const ln_int B = rm->n_bodies;
    for (ln_int b = 0; b < B; b++)
        for (int e = 0; e < 3; e++) {
            rd->v0[3 * b + e] = rd->v_prev[3 * b + e] = Y[NY * b + COL_V + e];
            rd->Pi0[3 * b + e] = rd->Pi_prev[3 * b + e] = Y[NY * b + COL_PI + e];
        }
    double dv = 0.0, dp = 0.0, sv = 1e-300, sp = 1e-300;
    for (int it = 0; it < IMPLICIT_KICK_ITERATIONS; it++) {
        for (ln_int b = 0; b < B; b++)
            for (int e = 0; e < 3; e++) {
                Y[NY * b + COL_V + e] = rd->v0[3 * b + e];
                Y[NY * b + COL_PI + e] = rd->Pi0[3 * b + e];
            }
        kick(rm, rd, Y, hk);
        dv = dp = 0.0;
        sv = sp = 1e-300;
        for (ln_int b = 0; b < B; b++)
            for (int e = 0; e < 3; e++) {
                const double v = Y[NY * b + COL_V + e], Pi = Y[NY * b + COL_PI + e];
                dv = larger(dv, fabs(v - rd->v_prev[3 * b + e]));
                dp = larger(dp, fabs(Pi - rd->Pi_prev[3 * b + e]));
                sv = larger(sv, fabs(v));
                sp = larger(sp, fabs(Pi));
            }
        evaluate_loads(m, d, Y, F_base);
        if (it > 0 && dv <= 8 * DBL_EPSILON * sv && dp <= 8 * DBL_EPSILON * sp) return 1;
        if (!(dv < 1e300 && dp < 1e300)) return 0;
        for (ln_int b = 0; b < B; b++)
            for (int e = 0; e < 3; e++) {
                rd->v_prev[3 * b + e] = Y[NY * b + COL_V + e];
                rd->Pi_prev[3 * b + e] = Y[NY * b + COL_PI + e];
            }
    }
    return dv <= 1e-10 * sv && dp <= 1e-10 * sp;
}

/* n_steps steps of size h, each the composition of base steps of gammas[g] h; the masses' X, U at the end. */
static int composition_steps(const ln_model *m, const ln_method *meth, ln_data *d, ln_int n_steps, double h,
                             ln_int *completed)
{
    const struct ln_rigid_model *rm = m->rigid;
    struct ln_rigid_data *rd = d->rigid;
    const ln_int B = rm->n_bodies;
    const double *F_base = d->F_base;
    double *Y = rd->Y;
    *completed = 0;
    evaluate_loads(m, d, Y, F_base);
    for (ln_int step = 0; step < n_steps; step++) {
        for (ln_int g = 0; g < meth->n_gammas; g++) {
            const double hs = meth->gammas[g] * h;
            /* the forces at the start of a stage are those the last one ended with (X, U unchanged) */
            kick(rm, rd, Y, 0.5 * hs);
            for (ln_int b = 0; b < B; b++)
                for (int e = 0; e < 3; e++) Y[NY * b + COL_C + e] += hs * Y[NY * b + COL_V + e];
            free_rotation(rm, Y, hs);
            evaluate_loads(m, d, Y, F_base);
            if (m->velocity_dependent) {
                if (!implicit_kick(m, d, Y, F_base, 0.5 * hs)) return LN_IMPLICIT_KICK_FAILED;
            } else {
                kick(rm, rd, Y, 0.5 * hs);
            }
        }
        for (ln_int b = 0; b < B; b++)
            for (int e = 0; e < 3; e++)
                if (!(isfinite(Y[NY * b + COL_C + e]) && isfinite(Y[NY * b + COL_V + e])
                      && isfinite(Y[NY * b + COL_PI + e]))) return LN_NON_FINITE;
        *completed = step + 1;
        d->fail_t = d->t + (double)(step + 1) * h;
    }
    mass_states(m, rd, Y, d->X, d->U);
    return LN_OK;
}

/* ---- embedded Runge-Kutta on the Newton-Euler equations -------------------------------------------- */

/* R of q / |q| for each body (the homogeneous form: a rotation for any non-zero q). */
static void body_rotations(ln_int B, const double *Y, double *R)
{
    for (ln_int b = 0; b < B; b++) {
        const double *q = Y + NY * b + COL_Q;
        const double w = q[0], x = q[1], y = q[2], z = q[3];
        const double s = 2.0 / (w * w + x * x + y * y + z * z);
        double *Rb = R + 9 * b;
        Rb[0] = 1.0 - s * (y * y + z * z);
        Rb[1] = s * (x * y - w * z);
        Rb[2] = s * (x * z + w * y);
        Rb[3] = s * (x * y + w * z);
        Rb[4] = 1.0 - s * (x * x + z * z);
        Rb[5] = s * (y * z - w * x);
        Rb[6] = s * (x * z - w * y);
        Rb[7] = s * (y * z + w * x);
        Rb[8] = 1.0 - s * (x * x + y * y);
    }
}

/* X_k = c + R r_k, U_k = v + R (w x r_k), w = Pi / I (body frame), for the masses of a body (R from
   body_rotations). */
static void body_mass_states(const ln_model *m, const double *Y, const double *R, double *X, double *U)
{
    const struct ln_rigid_model *rm = m->rigid;
    for (ln_int k = 0; k < m->K; k++) {
        const ln_int b = rm->body_of[k];
        if (b < 0) continue;
        const double *r = rm->r + 3 * k, *I = rm->inertia + 3 * b, *Yb = Y + NY * b, *Rb = R + 9 * b;
        const double r0 = r[0], r1 = r[1], r2 = r[2];
        const double w0 = Yb[COL_PI] / I[0], w1 = Yb[COL_PI + 1] / I[1], w2 = Yb[COL_PI + 2] / I[2];
        const double u0 = w1 * r2 - w2 * r1, u1 = w2 * r0 - w0 * r2, u2 = w0 * r1 - w1 * r0;
        for (int e = 0; e < 3; e++) {
            X[3 * k + e] = Yb[COL_C + e] + Rb[3 * e] * r0 + Rb[3 * e + 1] * r1 + Rb[3 * e + 2] * r2;
            U[3 * k + e] = Yb[COL_V + e] + Rb[3 * e] * u0 + Rb[3 * e + 1] * u1 + Rb[3 * e + 2] * u2;
        }
    }
}

/* dY/dt at Y; leaves R (rd->R), the masses' states X, U at Y in their arrays. */
static void body_derivative(const ln_model *m, ln_data *d, const double *Y, const double *F_base, double *X,
                            double *U, double *dY)
{
    const struct ln_rigid_model *rm = m->rigid;
    struct ln_rigid_data *rd = d->rigid;
    const double *R = rd->R;
    body_rotations(rm->n_bodies, Y, rd->R);
    body_mass_states(m, Y, R, X, U);
    loads(m, Y, X, forces(m, d, X, U, F_base), rd->f, rd->tau);
    for (ln_int b = 0; b < rm->n_bodies; b++) {
        const double *Yb = Y + NY * b, *I = rm->inertia + 3 * b, *Rb = R + 9 * b;
        const double *f = rd->f + 3 * b, *tau = rd->tau + 3 * b;
        double *dYb = dY + NY * b;
        const double P0 = Yb[COL_PI], P1 = Yb[COL_PI + 1], P2 = Yb[COL_PI + 2];
        const double w0 = P0 / I[0], w1 = P1 / I[1], w2 = P2 / I[2];
        const double qw = Yb[COL_Q], qx = Yb[COL_Q + 1], qy = Yb[COL_Q + 2], qz = Yb[COL_Q + 3];
        for (int e = 0; e < 3; e++) {
            dYb[COL_C + e] = Yb[COL_V + e];
            dYb[COL_V + e] = f[e] / rm->body_mass[b];
            /* Euler's equations in the body frame: dPi/dt = Pi x w + R^T tau */
            dYb[COL_PI + e] = Rb[e] * tau[0] + Rb[3 + e] * tau[1] + Rb[6 + e] * tau[2];
        }
        dYb[COL_PI] += P1 * w2 - P2 * w1;
        dYb[COL_PI + 1] += P2 * w0 - P0 * w2;
        dYb[COL_PI + 2] += P0 * w1 - P1 * w0;
        /* dq/dt = q (x) (0, w) / 2: R <- R Rot(w dt), the body-frame angular velocity on the right */
        dYb[COL_Q] = -0.5 * (qx * w0 + qy * w1 + qz * w2);
        dYb[COL_Q + 1] = 0.5 * (qw * w0 + qy * w2 - qz * w1);
        dYb[COL_Q + 2] = 0.5 * (qw * w1 + qz * w0 - qx * w2);
        dYb[COL_Q + 3] = 0.5 * (qw * w2 + qx * w1 - qy * w0);
    }
}

/* (dX, dU): the change of the masses' states for a change e of the body states at Y, to first order. The
   quaternion change is taken as the body-frame rotation vector theta = 2 vec(q* (x) e_q) / |q|^2; its part
   along q (a change of |q|, which the renormalisation removes) moves no mass. Applied to dY/dt at Y it gives
   the masses' (U_k, dU_k/dt) there. R: the rotations at Y. */
static void mass_tangent(const ln_model *m, struct ln_rigid_data *rd, const double *Y, const double *e,
                         const double *R, double *dX, double *dU)
{
    const struct ln_rigid_model *rm = m->rigid;
    double *th = rd->th;
    for (ln_int b = 0; b < rm->n_bodies; b++) {
        const double *q = Y + NY * b + COL_Q, *p = e + NY * b + COL_Q;
        const double qw = q[0], qx = q[1], qy = q[2], qz = q[3], pw = p[0], px = p[1], py = p[2], pz = p[3];
        const double s = 2.0 / (qw * qw + qx * qx + qy * qy + qz * qz);
        /* vec(q* (x) p) = q_w p_v - p_w q_v - q_v x p_v */
        th[3 * b] = s * (qw * px - pw * qx - (qy * pz - qz * py));
        th[3 * b + 1] = s * (qw * py - pw * qy - (qz * px - qx * pz));
        th[3 * b + 2] = s * (qw * pz - pw * qz - (qx * py - qy * px));
    }
    for (ln_int k = 0; k < m->K; k++) {
        const ln_int b = rm->body_of[k];
        if (b < 0) {
            for (int i = 0; i < 3; i++) dX[3 * k + i] = dU[3 * k + i] = 0.0;
            continue;
        }
        const double *r = rm->r + 3 * k, *I = rm->inertia + 3 * b, *Yb = Y + NY * b, *eb = e + NY * b;
        const double *Rb = R + 9 * b, *t = th + 3 * b;
        const double r0 = r[0], r1 = r[1], r2 = r[2], t0 = t[0], t1 = t[1], t2 = t[2];
        const double w0 = Yb[COL_PI] / I[0], w1 = Yb[COL_PI + 1] / I[1], w2 = Yb[COL_PI + 2] / I[2];
        const double a0 = eb[COL_PI] / I[0], a1 = eb[COL_PI + 1] / I[1], a2 = eb[COL_PI + 2] / I[2];
        const double x0 = t1 * r2 - t2 * r1, x1 = t2 * r0 - t0 * r2, x2 = t0 * r1 - t1 * r0;  /* theta x r */
        const double u0 = w1 * r2 - w2 * r1, u1 = w2 * r0 - w0 * r2, u2 = w0 * r1 - w1 * r0;  /* w x r */
        /* theta x (w x r) + (e_Pi / I) x r */
        const double y0 = t1 * u2 - t2 * u1 + a1 * r2 - a2 * r1;
        const double y1 = t2 * u0 - t0 * u2 + a2 * r0 - a0 * r2;
        const double y2 = t0 * u1 - t1 * u0 + a0 * r1 - a1 * r0;
        for (int i = 0; i < 3; i++) {
            dX[3 * k + i] = eb[COL_C + i] + Rb[3 * i] * x0 + Rb[3 * i + 1] * x1 + Rb[3 * i + 2] * x2;
            dU[3 * k + i] = eb[COL_V + i] + Rb[3 * i] * y0 + Rb[3 * i + 1] * y1 + Rb[3 * i + 2] * y2;
        }
    }
}

/* out = Y + h sum_{j<n} AB[row, j] KY[j] (AB has s columns; KY rows are (B,13) blocks). */
static void combine_rows(ln_int size, const double *Y, double h, const double *AB, ln_int s, ln_int row, ln_int n,
                         const double *KY, double *out)
{
    for (ln_int i = 0; i < size; i++) {
        double acc = 0.0;
        for (ln_int j = 0; j < n; j++) acc += AB[row * s + j] * KY[j * size + i];
        out[i] = Y[i] + h * acc;
    }
}

/* Hairer-Wanner's starting step on the masses' states, as the point-mass path chooses it: from the masses'
   (U, dU/dt) at Y (MU0 their accelerations) and at Y + h0 dY/dt. Uses d->Xs, Us, Uh, Xc and rd->Ys, Yn as
   scratch, and leaves rd->R at the trial point. */
static double starting_step(const ln_model *m, const ln_method *meth, ln_data *d, const double *Y, const double *dY,
                            const double *MU0, double span)
{
    struct ln_rigid_data *rd = d->rigid;
    const double *X = d->X, *U = d->U;
    const double rtol = meth->rtol, atol = meth->atol, n = 6.0 * (double)m->n_free;
    double d0 = 0.0, d1 = 0.0;
    for (ln_int f = 0; f < m->n_free; f++)
        for (int e = 0; e < 3; e++) {
            const ln_int i = 3 * m->free_idx[f] + e;
            const double sx = atol + rtol * fabs(X[i]), su = atol + rtol * fabs(U[i]);
            d0 += (X[i] / sx) * (X[i] / sx) + (U[i] / su) * (U[i] / su);
            d1 += (U[i] / sx) * (U[i] / sx) + (MU0[i] / su) * (MU0[i] / su);
        }
    d0 = ln_sqrt(d0 / n);
    d1 = ln_sqrt(d1 / n);
    const double h0 = ln_trial_step(d0, d1, span);
    const ln_int size = NY * m->rigid->n_bodies;
    for (ln_int i = 0; i < size; i++) rd->Ys[i] = Y[i] + h0 * dY[i];
    body_derivative(m, d, rd->Ys, d->F_base, d->Xs, d->Us, rd->Yn);
    double *U1 = d->Uh, *acc1 = d->Xc;  /* the masses' velocities and accelerations at the trial point */
    mass_tangent(m, rd, rd->Ys, rd->Yn, rd->R, U1, acc1);
    double d2 = 0.0;
    for (ln_int f = 0; f < m->n_free; f++)
        for (int e = 0; e < 3; e++) {
            const ln_int i = 3 * m->free_idx[f] + e;
            const double sx = atol + rtol * fabs(X[i]), su = atol + rtol * fabs(U[i]);
            const double dx = (U1[i] - U[i]) / sx, du = (acc1[i] - MU0[i]) / su;
            d2 += dx * dx + du * du;
        }
    d2 = ln_sqrt(d2 / n) / h0;
    return ln_starting_step(meth, h0, d1, d2, span);
}

/* The step loop from *t_inout: to t_target under error control (n_fixed = 0), or n_fixed steps of exactly
   d->h_next with none. On return rd->Y is the last accepted state, d->X, d->U its masses' states. */
static int rk_steps(const ln_model *m, const ln_method *meth, ln_data *d, double *t_inout, double t_target,
                    ln_int max_steps, ln_int n_fixed, ln_int *accepted)
{
    const struct ln_rigid_model *rm = m->rigid;
    struct ln_rigid_data *rd = d->rigid;
    const ln_int s = meth->n_stages, B = rm->n_bodies, size = NY * B, K3 = 3 * m->K;
    const double *F_base = d->F_base;
    double *Y = rd->Y, *Ys = rd->Ys, *Yn = rd->Yn, *KY = rd->KY, *MX = d->KX, *MU = d->KU;
    double *X = d->X, *U = d->U, *Xs = d->Xs, *Us = d->Us, *Xn = d->Xn, *Un = d->Un;
    double t = *t_inout;
    ln_int steps = 0;
    *accepted = 0;
    if (s < 1 || s > d->n_stages_allocated) return LN_BAD_ARGUMENT;
    /* masses of no body (anchors holding springs) keep their states in every copy */
    memcpy(Xs, X, (size_t)K3 * sizeof(double));
    memcpy(Us, U, (size_t)K3 * sizeof(double));
    memcpy(Xn, X, (size_t)K3 * sizeof(double));
    memcpy(Un, U, (size_t)K3 * sizeof(double));
    d->n_rhs++;
    body_derivative(m, d, Y, F_base, X, U, KY);
    /* the masses' velocities and accelerations at every stage: the error estimate is formed from them */
    mass_tangent(m, rd, Y, KY, rd->R, MX, MU);
    if (n_fixed == 0 && d->h_next <= 0.0) {
        d->n_rhs++;
        d->h_next = starting_step(m, meth, d, Y, KY, MU, t_target - t);
    }
    while (n_fixed > 0 ? steps < n_fixed : t < t_target) {
        const double remaining = t_target - t;
        const double h = n_fixed > 0 ? d->h_next : ln_controlled_step(d->h_next, t, t_target);
        if (h < 0.0) {
            d->fail_t = t;
            return LN_STEP_UNDERFLOW;
        }
        for (ln_int i = 1; i < s; i++) {
            combine_rows(size, Y, h, meth->AB, s, i, i, KY, Ys);
            body_derivative(m, d, Ys, F_base, Xs, Us, KY + i * size);
            if (n_fixed == 0) mass_tangent(m, rd, Ys, KY + i * size, rd->R, MX + i * K3, MU + i * K3);
        }
        combine_rows(size, Y, h, meth->AB, s, s, s, KY, Yn);
        body_derivative(m, d, Yn, F_base, Xn, Un, KY + s * size);
        mass_tangent(m, rd, Yn, KY + s * size, rd->R, MX + s * K3, MU + s * K3);
        d->n_rhs += s;
        double err = 0.0;
        if (n_fixed > 0) {
            for (ln_int i = 0; i < size; i++)
                if (!isfinite(Yn[i])) {
                    d->fail_t = t;
                    return LN_NON_FINITE;
                }
        } else {
            err = ln_rk_error_norm_3d(m, meth, X, U, Xn, Un, MX, MU, h);
        }
        if (!(err <= 1.0)) {  /* too large, or not finite */
            d->rejected++;
            d->h_next = ln_next_step_size(meth, h, d->h_next, err);
            continue;
        }
        if (n_fixed > 0) {
            t = t + h;
        } else {
            t = h == remaining ? t_target : t + h;
            d->h_next = ln_next_step_size(meth, h, d->h_next, err);
        }
        /* renormalise q. The masses' states do not change (the map uses q / |q|), and the derivative at the
           new point only scales its dq/dt by 1/|q|: it stays the first stage of the next step */
        double *Ks = KY + s * size;
        for (ln_int b = 0; b < B; b++) {
            double *q = Yn + NY * b + COL_Q, *dq = Ks + NY * b + COL_Q;
            const double norm = ln_sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
            for (int i = 0; i < 4; i++) {
                q[i] /= norm;
                dq[i] /= norm;
            }
        }
        memcpy(Y, Yn, (size_t)size * sizeof(double));
        memcpy(KY, Ks, (size_t)size * sizeof(double));
        memcpy(MX, MX + s * K3, (size_t)K3 * sizeof(double));
        memcpy(MU, MU + s * K3, (size_t)K3 * sizeof(double));
        memcpy(X, Xn, (size_t)K3 * sizeof(double));
        memcpy(U, Un, (size_t)K3 * sizeof(double));
        *t_inout = t;
        *accepted = ++steps;
        if (n_fixed == 0 && steps > max_steps) {
            d->fail_t = t;
            return LN_TOO_MANY_STEPS;
        }
    }
    return LN_OK;
}

/* ---- entry points ----------------------------------------------------------------------------------- */

int ln_rigid_advance(const ln_model *m, const ln_method *meth, ln_data *d, double t_target, ln_int max_steps,
                     ln_int *steps)
{
    *steps = 0;
    if (!m->rigid || !d->rigid) return LN_BAD_ARGUMENT;
    struct ln_rigid_data *rd = d->rigid;
    memcpy(rd->Y_start, rd->Y, (size_t)(NY * rd->n_bodies) * sizeof(double));
    if (meth->kind == LN_COMPOSITION) {
        const double span = t_target - d->t;
        const ln_int n = ln_fixed_step_count(span, meth->dt);
        if (n > max_steps) return LN_TOO_MANY_STEPS;
        return composition_steps(m, meth, d, n, span / (double)n, steps);
    }
    if (meth->kind == LN_RUNGE_KUTTA) {
        double t = d->t;
        return rk_steps(m, meth, d, &t, t_target, max_steps, 0, steps);
    }
    return LN_BAD_ARGUMENT;
}

void ln_rigid_restore(const ln_model *m, ln_data *d)
{
    (void)m;
    if (d->rigid) memcpy(d->rigid->Y, d->rigid->Y_start, (size_t)(NY * d->rigid->n_bodies) * sizeof(double));
}

void ln_rigid_get_state(const ln_model *m, const ln_data *d, double *Y)
{
    (void)m;
    if (d->rigid) memcpy(Y, d->rigid->Y, (size_t)(NY * d->rigid->n_bodies) * sizeof(double));
}

int ln_rigid_set_state(const ln_model *m, ln_data *d, const double *Y)
{
    if (!m->rigid || !d->rigid) return LN_BAD_ARGUMENT;
    const ln_int B = d->rigid->n_bodies;
    for (ln_int b = 0; b < B; b++) {
        const double *q = Y + NY * b + COL_Q;
        for (int i = 0; i < NY; i++)
            if (!isfinite(Y[NY * b + i])) return LN_BAD_ARGUMENT;
        if (q[0] == 0.0 && q[1] == 0.0 && q[2] == 0.0 && q[3] == 0.0) return LN_BAD_ARGUMENT;
    }
    memcpy(d->rigid->Y, Y, (size_t)(NY * B) * sizeof(double));
    mass_states(m, d->rigid, d->rigid->Y, d->X, d->U);
    return LN_OK;
}

int ln_rigid_rk_fixed_steps(const ln_model *m, const ln_method *meth, ln_data *d, double h, ln_int n)
{
    if (!m->rigid || !d->rigid || meth->kind != LN_RUNGE_KUTTA || n < 1 || !(h > 0.0 && isfinite(h)))
        return LN_BAD_ARGUMENT;
    if (!ln_base_forces(m, d, d->F_base)) return LN_NON_FINITE;
    struct ln_rigid_data *rd = d->rigid;
    const double h_next = d->h_next;
    double t = d->t;
    ln_int steps;
    memcpy(rd->Y_start, rd->Y, (size_t)(NY * rd->n_bodies) * sizeof(double));
    memcpy(d->X_start, d->X, (size_t)(3 * m->K) * sizeof(double));
    memcpy(d->U_start, d->U, (size_t)(3 * m->K) * sizeof(double));
    d->h_next = h;
    const int status = rk_steps(m, meth, d, &t, t + (double)n * h, n, n, &steps);
    d->h_next = h_next;
    if (status != LN_OK) {
        ln_rigid_restore(m, d);
        memcpy(d->X, d->X_start, (size_t)(3 * m->K) * sizeof(double));
        memcpy(d->U, d->U_start, (size_t)(3 * m->K) * sizeof(double));
        return status;
    }
    d->t = t;
    d->steps += steps;
    return LN_OK;
}

/* ---- the layout of the bodies (the numpy reference: linknet_core.structure.bodies) ------------------ */

#define TOP_TOL 1e-12  /* principal moments equal to this (relative): a spherical or symmetric top (bodies.TOP_TOL) */

/* Eigen-decomposition of a symmetric 3x3 matrix (row-major) by cyclic Jacobi rotations: eigenvalues w
   ascending, eigenvectors the columns of V. */
static void eigh3(const double *A_in, double *w, double *V)
{
    double A[9];
    memcpy(A, A_in, sizeof A);
    for (int i = 0; i < 9; i++) V[i] = (i % 4 == 0) ? 1.0 : 0.0;
    for (int sweep = 0; sweep < 64; sweep++) {
        const double off = A[1] * A[1] + A[2] * A[2] + A[5] * A[5];
        const double diag = A[0] * A[0] + A[4] * A[4] + A[8] * A[8];
        if (off <= 1e-40 * diag || off == 0.0) break;
        for (int p = 0; p < 2; p++)
            for (int q = p + 1; q < 3; q++) {
                const double apq = A[3 * p + q];
                if (apq == 0.0) continue;
                const double theta = (A[3 * q + q] - A[3 * p + p]) / (2.0 * apq);
                const double t = (theta >= 0.0 ? 1.0 : -1.0) / (fabs(theta) + ln_sqrt(theta * theta + 1.0));
                const double c = 1.0 / ln_sqrt(t * t + 1.0), sn = t * c;
                for (int k = 0; k < 3; k++) {
                    const double akp = A[3 * k + p], akq = A[3 * k + q];
                    A[3 * k + p] = c * akp - sn * akq;
                    A[3 * k + q] = sn * akp + c * akq;
                }
                for (int k = 0; k < 3; k++) {
                    const double apk = A[3 * p + k], aqk = A[3 * q + k];
                    A[3 * p + k] = c * apk - sn * aqk;
                    A[3 * q + k] = sn * apk + c * aqk;
                }
                for (int k = 0; k < 3; k++) {
                    const double vkp = V[3 * k + p], vkq = V[3 * k + q];
                    V[3 * k + p] = c * vkp - sn * vkq;
                    V[3 * k + q] = sn * vkp + c * vkq;
                }
            }
    }
    for (int i = 0; i < 3; i++) w[i] = A[4 * i];
    for (int i = 0; i < 2; i++)  /* ascending, columns with them */
        for (int j = 0; j < 2 - i; j++)
            if (w[j] > w[j + 1]) {
                const double tw = w[j];
                w[j] = w[j + 1];
                w[j + 1] = tw;
                for (int k = 0; k < 3; k++) {
                    const double tv = V[3 * k + j];
                    V[3 * k + j] = V[3 * k + j + 1];
                    V[3 * k + j + 1] = tv;
                }
            }
}

/* Unit quaternion (w, x, y, z) of a rotation matrix (row-major): Shepperd's branch by the largest term. */
static void quaternion_of(const double *R, double *q)
{
    const double t = R[0] + R[4] + R[8], d0 = R[0], d1 = R[4], d2 = R[8];
    const double terms[4] = {t, d0, d1, d2};
    int branch = 0;
    for (int i = 1; i < 4; i++)
        if (terms[i] > terms[branch]) branch = i;
    const double arg[4] = {t, d0 - d1 - d2, d1 - d0 - d2, d2 - d0 - d1};
    const double s = 2.0 * ln_sqrt(ln_fmax(1.0 + arg[branch], 0.0));
    const double a = R[7] - R[5], b = R[2] - R[6], c = R[3] - R[1];
    const double e = R[1] + R[3], f = R[2] + R[6], g = R[5] + R[7];
    switch (branch) {
    case 0: q[0] = s / 4; q[1] = a / s; q[2] = b / s; q[3] = c / s; break;
    case 1: q[0] = a / s; q[1] = s / 4; q[2] = e / s; q[3] = f / s; break;
    case 2: q[0] = b / s; q[1] = e / s; q[2] = s / 4; q[3] = g / s; break;
    default: q[0] = c / s; q[1] = f / s; q[2] = g / s; q[3] = s / 4; break;
    }
    const double n = ln_sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
    for (int i = 0; i < 4; i++) q[i] /= n;
}

int ln_rigid_layout(ln_int K, const double *mass, const double *X, const double *U, struct ln_rigid_model *rigid,
                    double *r, double *inertia_out, double *body_mass, ln_int *top, double *Y0)
{
    const ln_int B = rigid->n_bodies, *body_of = rigid->body_of;
    for (ln_int b = 0; b < B; b++) {
        double M = 0.0, c[3] = {0, 0, 0}, v[3] = {0, 0, 0}, I[9] = {0};
        for (ln_int k = 0; k < K; k++)
            if (body_of[k] == b) {
                M += mass[k];
                for (int e = 0; e < 3; e++) {
                    c[e] += mass[k] * X[3 * k + e];
                    v[e] += mass[k] * U[3 * k + e];
                }
            }
        if (!(M > 0.0)) return LN_BAD_ARGUMENT;
        for (int e = 0; e < 3; e++) {
            c[e] /= M;
            v[e] /= M;
        }
        for (ln_int k = 0; k < K; k++)
            if (body_of[k] == b) {
                const double rho[3] = {X[3 * k] - c[0], X[3 * k + 1] - c[1], X[3 * k + 2] - c[2]};
                const double sq = rho[0] * rho[0] + rho[1] * rho[1] + rho[2] * rho[2];
                for (int i = 0; i < 3; i++)
                    for (int j = 0; j < 3; j++)
                        I[3 * i + j] += -mass[k] * rho[i] * rho[j] + (i == j ? mass[k] * sq : 0.0);
            }
        double w[3], axes[9];
        eigh3(I, w, axes);
        const double scale = TOP_TOL * w[2];
        const int spherical = w[2] - w[0] <= scale;
        const int first_pair_equal = w[1] - w[0] <= scale;
        const int symmetric = first_pair_equal || w[2] - w[1] <= scale;
        const int kind = spherical ? LN_SPHERICAL_TOP : symmetric ? LN_SYMMETRIC_TOP : LN_ASYMMETRIC_TOP;
        const int order[3] = {kind == LN_SYMMETRIC_TOP && !first_pair_equal ? 1 : 0,
                              kind == LN_SYMMETRIC_TOP && !first_pair_equal ? 2 : 1,
                              kind == LN_SYMMETRIC_TOP && !first_pair_equal ? 0 : 2};
        double frame[9], inertia[3];
        for (int j = 0; j < 3; j++) {
            inertia[j] = w[order[j]];
            for (int i = 0; i < 3; i++) frame[3 * i + j] = axes[3 * i + order[j]];
        }
        if (kind == LN_SYMMETRIC_TOP) inertia[0] = inertia[1] = 0.5 * (inertia[0] + inertia[1]);
        if (kind == LN_SPHERICAL_TOP) {
            for (int i = 0; i < 9; i++) frame[i] = (i % 4 == 0) ? 1.0 : 0.0;
            inertia[0] = inertia[1] = inertia[2] = (w[0] + w[1] + w[2]) / 3.0;
        }
        const double det = frame[0] * (frame[4] * frame[8] - frame[5] * frame[7])
                           - frame[1] * (frame[3] * frame[8] - frame[5] * frame[6])
                           + frame[2] * (frame[3] * frame[7] - frame[4] * frame[6]);
        if (det < 0.0)
            for (int i = 0; i < 3; i++) frame[3 * i] = -frame[3 * i];
        double *Y = Y0 + LN_RIGID_STATE * b, R0[9];
        quaternion_of(frame, Y + COL_Q);
        rotation_matrices(1, Y, R0);  /* exactly the matrix the steps use */
        double Lm[3] = {0, 0, 0};
        for (ln_int k = 0; k < K; k++)
            if (body_of[k] == b) {
                const double rho[3] = {X[3 * k] - c[0], X[3 * k + 1] - c[1], X[3 * k + 2] - c[2]};
                const double du[3] = {U[3 * k] - v[0], U[3 * k + 1] - v[1], U[3 * k + 2] - v[2]};
                for (int i = 0; i < 3; i++)  /* r = R0^T rho: in the frame of exactly the matrix the steps use */
                    r[3 * k + i] = R0[i] * rho[0] + R0[3 + i] * rho[1] + R0[6 + i] * rho[2];
                Lm[0] += mass[k] * (rho[1] * du[2] - rho[2] * du[1]);
                Lm[1] += mass[k] * (rho[2] * du[0] - rho[0] * du[2]);
                Lm[2] += mass[k] * (rho[0] * du[1] - rho[1] * du[0]);
            }
        for (int e = 0; e < 3; e++) {
            Y[e] = c[e];
            Y[3 + e] = v[e];
            Y[10 + e] = R0[e] * Lm[0] + R0[3 + e] * Lm[1] + R0[6 + e] * Lm[2];  /* Pi = R^T L, body frame */
        }
        body_mass[b] = M;
        top[b] = kind;
        for (int e = 0; e < 3; e++) inertia_out[3 * b + e] = inertia[e];
    }
    for (ln_int k = 0; k < K; k++)
        if (body_of[k] < 0)
            for (int e = 0; e < 3; e++) r[3 * k + e] = 0.0;
    rigid->r = r;
    rigid->inertia = inertia_out;
    rigid->body_mass = body_mass;
    rigid->kind = top;
    return LN_OK;
}
