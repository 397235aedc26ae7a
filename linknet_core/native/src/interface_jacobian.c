/* Interface Jacobians: the derivatives of the outputs T, Freact and dU/dt with respect to the inputs F, P, V, A at
 * a fixed state (interface_jacobian.h). The formulas are those of the numpy reference,
 * linknet_core/dynamics/interface_jacobian.py, which derives them; in short, along a seed with dX, dU the seed's
 * P, V on the driven rows:
 *
 *   dE_l = (dX_k2 - dX_k1) / R_l                                                                   (8)
 *   dB_l = 2 (U_k2 - U_k1) . (dU_k2 - dU_k1) / R_l + dE_l . (a_k2 - a_k1) + E_l . (da_k2 - da_k1)  (26)
 *   dA y = dC M^-1 C^T y + C M^-1 dC^T y                                                          (25)
 *   A regular:  dT = A^-1 (dB - dA T)                    (one solve with the factorisation of T's evaluation)
 *   A singular: dT = A^+ (dB - dA T) + A^+ A^+ dA (I - Pi) B + (I - Pi) dA A^+ T,  Pi = A A^+
 *               (the pseudo-inverse's derivative at constant rank: three solves)
 *   d(C^T T) = C^T dT + dC^T T;  dacc = (dF + d(C^T T)) / M on free masses, dA on driven anchors;
 *   dFreact = the anchored rows of d(C^T T).
 *
 * The workspace keeps its own ln_data, evaluated by ln_evaluate (the one definition of the outputs), whose
 * factorisation of A (chain sweeps, sparse LDL^T or minimum-norm) every directional derivative reuses.
 *
 * Ropes: the derivatives of the current mode's outputs. ln_evaluate chooses the mode of the state (the acceleration
 * LCP on the touching ropes, stages/ropes.c) and factors that mode's A; the formulas above then run on the mode's
 * model, a copy of the model whose 1/R_l is 0 on the slack ropes (as the core's stages run a mode): a slack rope
 * has E_l = 0, no term of (26) and a unit diagonal in A, hence dT_l = 0. The mode is held: an input that would
 * change it gives the one-sided derivative of the current mode's outputs.
 *
 * A frictionless ground: each contact is one of those unilateral links, from its mass to a virtual anchor placed
 * straight above it (ln_contacts_place: Q = X_k + (R_c - g_k) n, moving with the mass along the plane), so that its
 * E is along n, its term of (26) is (n . U_k)^2 / R_c and its tension is the ground's normal force; an active
 * contact is taut in the mode, a mass in flight's is slack. The anchors are placed from the state alone (the
 * mass's X_k and U_k, no input), so their dX and dU along any seed are 0; an anchor is fixed (infinite mass), so
 * its da is 0 here, where the mode's anchor accelerates with its mass along the plane: that acceleration enters
 * (26) only as E . a_Q, zero since E is along n, so its derivative contributes nothing either. The normal force
 * still answers the inputs (dT of the contact's link), and through it the masses' accelerations. The model's extra
 * rows (the contacts' links, the anchors' masses) come after the scene's; the caller keeps the scene's. A rough
 * ground's grips and sliding loads are not linearized (LN_NOT_LINEARIZABLE; the library refuses it first): the
 * sliding contacts' friction -mu N d carries non-symmetric columns into the system that these solves do not.
 */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "drive.h"
#include "interface_jacobian.h"
#include "linknet.h"
#include "ln_math.h"

#define FN(name) name##_3d
#include "stages.h"
#undef FN

struct ln_interface {
    ln_data *d;                     /* private: the evaluation at the prepared state and its factorisation of A */
    int prepared, singular;
    ln_int drag, spring, quadratic_drag;    /* the core's codes of the force element kinds (ln_force_kind) */
    /* the prepared state: X, U with the driven rows at P, V; a_k of (26) (F/M on free masses, A_a on driven
       anchors); E (8); T; g = M^-1 C^T T */
    double *X, *U, *F, *a, *E, *T, *g;
    double *T_solved, *inconsistent;    /* A singular: A^+ T and (I - Pi) B */
    double *mode_inv_R;                 /* ropes: 1/R_l of the prepared state's mode, 0 on its slack ropes */
    /* scratch of one directional derivative */
    double *dX, *dU, *dF, *da, *dE, *h, *p, *q, *link, *rhs, *y, *z, *w, *dT;
};

static double *zeros(ln_int n) { return calloc((size_t)(n > 0 ? n : 1), sizeof(double)); }

void ln_interface_free(ln_interface *J)
{
    if (!J) return;
    double *arrays[] = {J->X, J->U, J->F, J->a, J->E, J->T, J->g, J->T_solved, J->inconsistent, J->mode_inv_R,
                        J->dX, J->dU, J->dF,
                        J->da, J->dE, J->h, J->p, J->q, J->link, J->rhs, J->y, J->z, J->w, J->dT};
    for (size_t i = 0; i < sizeof arrays / sizeof arrays[0]; i++) free(arrays[i]);
    ln_data_free(J->d);
    free(J);
}

ln_interface *ln_interface_new(const ln_model *m)
{
    ln_interface *J = calloc(1, sizeof *J);
    if (!J) return NULL;
    const ln_int K3 = 3 * m->K, L = m->L;
    J->d = ln_data_new(m, 0);
    J->drag = ln_force_kind("drag");
    J->spring = ln_force_kind("spring");
    J->quadratic_drag = ln_force_kind("quadratic_drag");
    J->X = zeros(K3); J->U = zeros(K3); J->F = zeros(K3); J->a = zeros(K3); J->E = zeros(3 * L); J->T = zeros(L);
    J->g = zeros(K3); J->T_solved = zeros(L); J->inconsistent = zeros(L); J->mode_inv_R = zeros(L);
    J->dX = zeros(K3); J->dU = zeros(K3); J->dF = zeros(K3); J->da = zeros(K3); J->dE = zeros(3 * L);
    J->h = zeros(K3); J->p = zeros(K3); J->q = zeros(K3); J->link = zeros(K3);
    J->rhs = zeros(L); J->y = zeros(L); J->z = zeros(L); J->w = zeros(L); J->dT = zeros(L);
    if (!(J->d && J->X && J->U && J->F && J->a && J->E && J->T && J->g && J->T_solved && J->inconsistent
          && J->mode_inv_R && J->dX
          && J->dU && J->dF && J->da && J->dE && J->h && J->p && J->q && J->link && J->rhs && J->y && J->z && J->w
          && J->dT)) {
        ln_interface_free(J);
        return NULL;
    }
    return J;
}

int ln_interface_singular(const ln_interface *J) { return J->prepared && J->singular; }

/* out = M^-1 C(E)^T y: what link forces y do to the free masses' accelerations (zero on anchors) */
static void link_accelerations(const ln_model *m, const double *E, const double *y, double *out)
{
    memset(out, 0, (size_t)(3 * m->K) * sizeof(double));
    ln_add_correction_3d(m, E, y, 1.0, out);
}

/* (C(E) v)_l = E_l . (v_k1 - v_k2) */
static double link_row(const ln_model *m, const double *E, const double *v, ln_int l)
{
    const double *e = E + 3 * l, *va = v + 3 * m->k1[l], *vb = v + 3 * m->k2[l];
    return e[0] * (va[0] - vb[0]) + e[1] * (va[1] - vb[1]) + e[2] * (va[2] - vb[2]);
}

/* out = A y = C M^-1 C^T y */
static void A_times(const ln_model *m, ln_interface *J, const double *y, double *out)
{
    link_accelerations(m, J->E, y, J->p);
    for (ln_int l = 0; l < m->L; l++) out[l] = link_row(m, J->E, J->p, l);
}

/* out = dA y = dC M^-1 C^T y + C M^-1 dC^T y, dC built from J->dE */
static void dA_times(const ln_model *m, ln_interface *J, const double *y, double *out)
{
    link_accelerations(m, J->E, y, J->p);
    link_accelerations(m, J->dE, y, J->q);
    for (ln_int l = 0; l < m->L; l++) out[l] = link_row(m, J->dE, J->p, l) + link_row(m, J->E, J->q, l);
}

/* The model the formulas run on: ``m`` itself, or with ropes its mode's copy (1/R_l 0 on the slack ropes) in *mode. */
static const ln_model *mode_model(const ln_model *m, const ln_interface *J, ln_model *mode)
{
    if (!m->n_ropes) return m;
    *mode = *m;
    mode->inv_R = J->mode_inv_R;
    return mode;
}

int ln_interface_prepare(const ln_model *m_scene, ln_interface *J, const ln_data *source, const double *X,
                         const double *U, const double *F_input)
{
    ln_data *d = J->d;
    const ln_model *m = m_scene;
    const ln_int K3 = 3 * m->K, L = m->L, n3 = 3 * m->n_driven;
    J->prepared = 0;
    /* a rough ground's friction (its grips, the sliding contacts' loads) is not linearized here (the library
       refuses first; this guards any other caller) */
    if (m->n_grips) return LN_NOT_LINEARIZABLE;
    /* the caller's time and anchors' motion, and the input forces */
    d->t = source->t;
    if (F_input) memcpy(d->F_input, F_input, (size_t)K3 * sizeof(double));
    else memset(d->F_input, 0, (size_t)K3 * sizeof(double));
    d->drive_t0 = source->drive_t0;
    d->drive_hold_t = source->drive_hold_t;
    memcpy(d->drive_P, source->drive_P, (size_t)n3 * sizeof(double));
    memcpy(d->drive_V, source->drive_V, (size_t)n3 * sizeof(double));
    memcpy(d->drive_A, source->drive_A, (size_t)n3 * sizeof(double));
    d->drive_callback = source->drive_callback;
    d->drive_user = source->drive_user;
    /* the state as the outputs see it: the driven rows at P, V, and the base forces with their rows at A */
    memcpy(J->X, X, (size_t)K3 * sizeof(double));
    memcpy(J->U, U, (size_t)K3 * sizeof(double));
    if (m->n_contacts) ln_contacts_place_3d(m, J->X, J->U);  /* each contact's anchor above its mass, from the state */
    if (!ln_base_forces(m, d, J->F)) return LN_NON_FINITE;
    int status = ln_drive_rows(m, d, d->t, J->X, J->U, J->F, 3);
    if (status != LN_OK) return status;
    if ((status = ln_evaluate(m, d, J->X, J->U)) != LN_OK) return status;
    ln_model mode;
    if (m->n_ropes) {  /* the mode ln_evaluate chose (stages/ropes.c leaves its taut ropes in rope_flags' 5th set) */
        const uint8_t *taut = d->rope_flags + 4 * m->n_ropes;
        memcpy(J->mode_inv_R, m->inv_R, (size_t)L * sizeof(double));
        for (ln_int r = 0; r < m->n_ropes; r++)
            if (!taut[r]) J->mode_inv_R[m->rope_link[r]] = 0.0;
        m = mode_model(m_scene, J, &mode);
    }
    if (m->n_elements > 0) {
        memcpy(J->dF, J->F, (size_t)K3 * sizeof(double));  /* dF as scratch: the base forces */
        ln_scene_forces_3d(m, J->X, J->U, J->dF, J->F);
    }
    for (ln_int k = 0; k < m->K; k++)
        for (int e = 0; e < 3; e++) J->a[3 * k + e] = m->accel_weight[k] * J->F[3 * k + e];
    ln_unit_vectors_3d(m, J->X, J->E);
    memcpy(J->T, d->T, (size_t)L * sizeof(double));
    link_accelerations(m, J->E, J->T, J->g);
    J->singular = L > 0 && d->singular;
    if (J->singular) {
        /* the minimum-norm route (general_tensions) leaves B of (26) in d->B */
        A_times(m, J, J->T, J->y);
        for (ln_int l = 0; l < L; l++) J->inconsistent[l] = d->B[l] - J->y[l];
        ln_solve_tension_system_3d(m, d, J->T, J->T_solved);
    }
    J->prepared = 1;
    return LN_OK;
}

/* The kinds element_derivatives differentiates (each has its branch there). */
static const char *const derivative_kinds[] = {"drag", "quadratic_drag", "spring"};

const char *ln_interface_kind_name(ln_int i)
{
    return i >= 0 && i < (ln_int)(sizeof derivative_kinds / sizeof derivative_kinds[0]) ? derivative_kinds[i] : NULL;
}

/* The force elements' derivative along (dX, dU) added into dF (the formulas of stages/forces.c differentiated; the
   numpy reference's ELEMENT_DERIVATIVES). */
static void element_derivatives(const ln_model *m, const ln_interface *J, const double *X, const double *U,
                                const double *dX, const double *dU, double *dF)
{
    for (ln_int i = 0; i < m->n_elements; i++) {
        const ln_int a = m->element_mass[2 * i], b = m->element_mass[2 * i + 1], kind = m->element_kind[i];
        const double *p = m->element_param + LN_FORCE_PARAMETERS * i;
        if (kind == J->drag) {
            for (int e = 0; e < 3; e++) dF[3 * a + e] -= p[0] * dU[3 * a + e];
        } else if (kind == J->quadratic_drag) {
            const double *u = U + 3 * a, *du = dU + 3 * a;
            const double speed = ln_sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
            const double along = speed > 0.0 ? (u[0] * du[0] + u[1] * du[1] + u[2] * du[2]) / speed : 0.0;
            for (int e = 0; e < 3; e++) dF[3 * a + e] -= p[0] * (speed * du[e] + along * u[e]);
        } else if (kind == J->spring) {
            double d[3], dd[3], du[3], ddu[3], sq = 0.0;
            for (int e = 0; e < 3; e++) {
                d[e] = X[3 * b + e] - X[3 * a + e];
                dd[e] = dX[3 * b + e] - dX[3 * a + e];
                du[e] = U[3 * b + e] - U[3 * a + e];
                ddu[e] = dU[3 * b + e] - dU[3 * a + e];
                sq += d[e] * d[e];
            }
            const double dist = ln_sqrt(sq);
            if (dist == 0.0) continue;  /* coincident ends: no force, no derivative */
            double n[3], dn[3], n_dd = 0.0;
            for (int e = 0; e < 3; e++) {
                n[e] = d[e] / dist;
                n_dd += n[e] * dd[e];
            }
            double rate = 0.0, drate = 0.0;
            for (int e = 0; e < 3; e++) {
                dn[e] = (dd[e] - n[e] * n_dd) / dist;
                rate += n[e] * du[e];
                drate += dn[e] * du[e] + n[e] * ddu[e];
            }
            const double f = p[0] * (dist - p[1]) + p[2] * rate, df = p[0] * n_dd + p[2] * drate;
            for (int e = 0; e < 3; e++) {
                const double dfn = df * n[e] + f * dn[e];
                dF[3 * a + e] += dfn;
                dF[3 * b + e] -= dfn;
            }
        } else {  /* a kind without a derivative here: never skipped silently, the result is NaN */
            for (int e = 0; e < 3; e++) dF[3 * a + e] = NAN;
        }
    }
}

int ln_interface_directional(const ln_model *m_scene, ln_interface *J, const double *dF_in, const double *dP,
                             const double *dV, const double *dA, double *dT_out, double *dFreact, double *dacc)
{
    if (!J->prepared) return LN_BAD_ARGUMENT;
    ln_model mode;
    const ln_model *m = mode_model(m_scene, J, &mode);
    ln_data *d = J->d;
    const ln_int K = m->K, L = m->L, K3 = 3 * K;
    double *dX = J->dX, *dU = J->dU, *dF = J->dF, *da = J->da, *dE = J->dE, *dT = J->dT;
    memset(dX, 0, (size_t)K3 * sizeof(double));
    memset(dU, 0, (size_t)K3 * sizeof(double));
    for (ln_int j = 0; j < m->n_driven; j++)
        for (int e = 0; e < 3; e++) {
            const ln_int i = 3 * m->driven_idx[j] + e;
            dX[i] = dP ? dP[3 * j + e] : 0.0;
            dU[i] = dV ? dV[3 * j + e] : 0.0;
        }
    /* dF: the input's seed and the force elements' answer to the anchors' motion; none acts on an anchor */
    for (ln_int i = 0; i < K3; i++) dF[i] = dF_in ? dF_in[i] : 0.0;
    if (m->n_elements > 0) element_derivatives(m, J, J->X, J->U, dX, dU, dF);
    for (ln_int k = 0; k < K; k++)
        for (int e = 0; e < 3; e++) {
            if (m->is_fixed[k]) dF[3 * k + e] = 0.0;
            da[3 * k + e] = m->inv_m[k] * dF[3 * k + e];
        }
    for (ln_int j = 0; j < m->n_driven; j++)
        for (int e = 0; e < 3; e++) da[3 * m->driven_idx[j] + e] = dA ? dA[3 * j + e] : 0.0;

    if (L > 0) {
        ln_unit_vectors_3d(m, dX, dE);  /* (8) is linear in X */
        link_accelerations(m, dE, J->T, J->h);  /* M^-1 dC^T T */
        for (ln_int l = 0; l < L; l++) {
            const ln_int a = m->k1[l], b = m->k2[l];
            const double *E = J->E + 3 * l, *de = dE + 3 * l;
            double s = 0.0;
            for (int e = 0; e < 3; e++) {
                const ln_int ia = 3 * a + e, ib = 3 * b + e;
                s += 2.0 * (J->U[ib] - J->U[ia]) * (dU[ib] - dU[ia]) * m->inv_R[l]   /* dB (26) */
                     + de[e] * (J->a[ib] - J->a[ia]) + E[e] * (da[ib] - da[ia])
                     - de[e] * (J->g[ia] - J->g[ib]) - E[e] * (J->h[ia] - J->h[ib]);  /* - dA T */
            }
            J->rhs[l] = s;
        }
        ln_solve_tension_system_3d(m, d, J->rhs, dT);
        if (J->singular) {  /* the pseudo-inverse's derivative: the range of A turns with the geometry */
            dA_times(m, J, J->inconsistent, J->y);
            ln_solve_tension_system_3d(m, d, J->y, J->z);
            ln_solve_tension_system_3d(m, d, J->z, J->y);
            dA_times(m, J, J->T_solved, J->w);
            ln_solve_tension_system_3d(m, d, J->w, J->z);
            A_times(m, J, J->z, J->rhs);
            for (ln_int l = 0; l < L; l++) dT[l] += J->y[l] + (J->w[l] - J->rhs[l]);  /* (I - Pi) w */
        }
    }
    /* d(C^T T) = C^T dT + dC^T T: +f on k1(l), -f on k2(l) */
    double *link = J->link, total = 0.0;
    memset(link, 0, (size_t)K3 * sizeof(double));
    for (ln_int l = 0; l < L; l++) {
        const ln_int a = m->k1[l], b = m->k2[l];
        for (int e = 0; e < 3; e++) {
            const double f = dT[l] * J->E[3 * l + e] + J->T[l] * dE[3 * l + e];
            link[3 * a + e] += f;
            link[3 * b + e] -= f;
        }
        total += dT[l];
    }
    if (dT_out) memcpy(dT_out, dT, (size_t)L * sizeof(double));
    if (dFreact)
        for (ln_int i = 0; i < m->n_fixed; i++)
            for (int e = 0; e < 3; e++) dFreact[3 * i + e] = link[3 * m->fixed_idx[i] + e];
    for (ln_int i = 0; i < K3; i++) total += link[i] + dF[i];
    if (dacc) {
        for (ln_int k = 0; k < K; k++)
            for (int e = 0; e < 3; e++) dacc[3 * k + e] = m->inv_m[k] * (dF[3 * k + e] + link[3 * k + e]);
        for (ln_int j = 0; j < m->n_driven; j++)
            for (int e = 0; e < 3; e++) dacc[3 * m->driven_idx[j] + e] = dA ? dA[3 * j + e] : 0.0;
    }
    return isfinite(total) ? LN_OK : LN_NON_FINITE;
}
