/* Driven anchors: anchored masses (1/M = 0) whose motion P_a(t) is prescribed (linknet_core/scene/motion.py
 * describes the kinds; linknet_core/dynamics/drive.py is the numpy reference of all of this).
 *
 * A driven anchor's rows of X and U hold P_a and V_a. For a link l between a free mass k and a driven anchor a the
 * constraint |X_k - P_a(t)|^2 = R_l^2 (11) differentiated once is (12) with the relative velocity U_k - V_a, and
 * twice is (13) with dU_a/dt = A_a(t): B_l of (26) becomes |U_k2 - U_k1|^2 / R_l + E_l . (a_k2 - a_k1) with
 * a = F/M on free masses and a = A_a on the driven anchor, while A of (25) is unchanged (1/M_a = 0). RATTLE's
 * position stage targets P_a(t + h) and its velocity stage V_a(t + h) (stages/rattle.c); the Runge-Kutta stages
 * take the anchors as known functions of time (stages/runge_kutta.c).
 *
 * Motions: piecewise cubics (constant velocity, clamped splines through waypoints, input-driven anchors at rest)
 * as rows (start, base, c0..c3 per axis) in powers of tau - base, tau = t - drive_t0; sines
 * P = origin + a (sin(w tau + phi) - sin(phi)); input-driven anchors the held quadratic or the callback.
 */
#include <math.h>
#include <string.h>

#include "drive.h"
#include "linknet.h"
#include "ln_math.h"

enum ln_motion_kind { LN_MOTION_INPUT = 0, LN_MOTION_PIECEWISE = 1, LN_MOTION_SINE = 2 };

#define PIECE_COLUMNS 14

static void piecewise_cubic(const ln_model *m, ln_int a, double tau, double *P, double *V, double *A)
{
    /* the last row that starts at or before tau (the first row starts at -inf) */
    ln_int lo = m->motion_pieces[a], hi = m->motion_pieces[a + 1] - 1;
    while (lo < hi) {
        const ln_int mid = lo + (hi - lo + 1) / 2;
        if (m->piece[PIECE_COLUMNS * mid] <= tau) lo = mid;
        else hi = mid - 1;
    }
    const double *row = m->piece + PIECE_COLUMNS * lo;
    const double s = tau - row[1];
    for (int e = 0; e < 3; e++) {
        const double *c = row + 2 + 4 * e;
        P[e] = c[0] + s * (c[1] + s * (c[2] + s * c[3]));
        V[e] = c[1] + s * (2.0 * c[2] + s * 3.0 * c[3]);
        A[e] = 2.0 * c[2] + 6.0 * s * c[3];
    }
}

static void sine(const ln_model *m, ln_int a, double tau, double *P, double *V, double *A)
{
    const double *q = m->sine + 12 * a, *origin = q, *amplitude = q + 3, *omega = q + 6, *phase = q + 9;
    for (int e = 0; e < 3; e++) {
        const double angle = omega[e] * tau + phase[e], sn = ln_sin(angle), cs = ln_cos(angle);
        P[e] = origin[e] + amplitude[e] * (sn - ln_sin(phase[e]));
        V[e] = amplitude[e] * omega[e] * cs;
        A[e] = -amplitude[e] * omega[e] * omega[e] * sn;
    }
}

int ln_drive_at(const ln_model *m, ln_data *d, double t, double *P, double *V, double *A)
{
    const double tau = t - d->drive_t0, s = t - d->drive_hold_t;
    const double *given = d->drive_scratch + 9 * m->n_driven;  /* the callback's values, 9 per input anchor */
    if (d->drive_callback && d->drive_callback(d->drive_user, t, d->drive_scratch + 9 * m->n_driven) != 0)
        return LN_DRIVE_FAILED;
    double total = 0.0;
    for (ln_int a = 0; a < m->n_driven; a++) {
        double *p = P + 3 * a, *v = V + 3 * a, *acc = A + 3 * a;
        switch (m->motion_kind[a]) {
        case LN_MOTION_SINE:
            sine(m, a, tau, p, v, acc);
            break;
        case LN_MOTION_INPUT:
            if (d->drive_callback) {
                for (int e = 0; e < 3; e++) {
                    p[e] = given[e];
                    v[e] = given[3 + e];
                    acc[e] = given[6 + e];
                }
                given += 9;
            } else {
                const double *P0 = d->drive_P + 3 * a, *V0 = d->drive_V + 3 * a, *A0 = d->drive_A + 3 * a;
                for (int e = 0; e < 3; e++) {
                    p[e] = P0[e] + s * V0[e] + (0.5 * s * s) * A0[e];
                    v[e] = V0[e] + s * A0[e];
                    acc[e] = A0[e];
                }
            }
            break;
        default:
            piecewise_cubic(m, a, tau, p, v, acc);
            break;
        }
        for (int e = 0; e < 3; e++) total += p[e] + v[e] + acc[e];
    }
    return isfinite(total) ? LN_OK : LN_DRIVE_FAILED;
}

int ln_drive_rows(const ln_model *m, ln_data *d, double t, double *X, double *U, double *F, int dim)
{
    double *P = d->drive_scratch, *V = P + 3 * m->n_driven, *A = V + 3 * m->n_driven;
    const int status = ln_drive_at(m, d, t, P, V, A);
    if (status != LN_OK) return status;
    for (ln_int a = 0; a < m->n_driven; a++) {
        const ln_int k = m->driven_idx[a];
        for (int e = 0; e < dim; e++) {
            if (X) X[k * dim + e] = P[3 * a + e];
            if (U) U[k * dim + e] = V[3 * a + e];
            if (F) F[k * dim + e] = A[3 * a + e];
        }
    }
    return LN_OK;
}

static int drive_jump(const ln_model *m, const ln_method *meth, ln_data *d)
{
    const ln_int n = m->n_driven;
    double *P = d->drive_scratch, *V = P + 3 * n, *A = V + 3 * n, *X = d->X, *U = d->U;
    int status = ln_drive_at(m, d, d->t, P, V, A);
    if (status != LN_OK) return status;
    double jump_x = 0.0, jump_u = 0.0;
    for (ln_int a = 0; a < n; a++) {
        const ln_int k = m->driven_idx[a];
        for (int e = 0; e < 3; e++) {
            jump_x = ln_fmax(jump_x, fabs(P[3 * a + e] - X[3 * k + e]));
            jump_u = ln_fmax(jump_u, fabs(V[3 * a + e] - U[3 * k + e]));
        }
    }
    for (ln_int i = 0; i < 3 * n; i++) d->impulse[i] = 0.0;
    d->jump_position = jump_x;
    d->jump_velocity = jump_u;
    if (jump_x == 0.0 && jump_u == 0.0) return LN_OK;
    if (m->n_ropes) {  /* with ropes a jump is an impact on the ropes it stretches or jerks (stages/ropes.c) */
        d->jumps++;
        return ln_rope_anchor_jump(m, meth, d, P, V);
    }
    for (ln_int a = 0; a < n; a++) {
        const ln_int k = m->driven_idx[a];
        for (int e = 0; e < 3; e++) {
            X[3 * k + e] = P[3 * a + e];
            U[3 * k + e] = V[3 * a + e];
        }
    }
    d->jumps++;
    if (m->L == 0) return LN_OK;
    /* the free masses follow the anchors' new positions onto (11) in the mass metric (when the anchors moved), and
       U onto (12) relative to the anchors' new velocities: the closest velocities, U -= M^-1 C^T mu */
    if ((status = ln_project_state(m, d, X, U, jump_x > 0.0, meth->position_tol, meth->max_projection_iter, d->mu))
        != LN_OK)
        return status;
    const double *E = d->E0, *mu = d->mu;
    /* the anchors' rows of C^T mu: +mu_l E_l on k1(l), -mu_l E_l on k2(l) */
    for (ln_int l = 0; l < m->L; l++)
        for (ln_int a = 0; a < n; a++) {
            const ln_int k = m->driven_idx[a];
            const double sign = m->k1[l] == k ? 1.0 : m->k2[l] == k ? -1.0 : 0.0;
            if (sign == 0.0) continue;
            for (int e = 0; e < 3; e++) d->impulse[3 * a + e] -= sign * mu[l] * E[3 * l + e];
        }
    return LN_OK;
}

int ln_drive_jump(const ln_model *m, const ln_method *meth, ln_data *d)
{
    const int status = drive_jump(m, meth, d);
    /* the jump's own impulse, which the advance's events (with ropes) add to in d->impulse */
    memcpy(d->jump_impulse, d->impulse, (size_t)(3 * m->n_driven) * sizeof(double));
    return status;
}
