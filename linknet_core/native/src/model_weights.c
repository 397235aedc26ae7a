/* What of the model follows from the masses, lengths and gravity: 1/M, the base forces, 1/R, the weights of A (25)
 * pair by pair and along a chain, and the weights of a_k in B (26). The one formula for them: the Python binding
 * (linknet_core.native.model.NativeModel) builds every model with it, and the self-contained FMU rebuilds its model
 * with it when a mass, a length or gravity changes, so both run the same arithmetic bit for bit.
 *
 * Setup, not a step: called once per model build.
 */
#include <stdlib.h>

#include "linknet.h"

ln_int ln_model_weights_size(const ln_model *m)
{
    const ln_int chain = m->solver == LN_SOLVER_CHAIN ? 2 * m->L : 0;
    return 5 * m->K + m->L + m->n_pairs + chain;
}

int ln_model_weights(ln_model *m, const double *mass, const double *R, const double *gravity,
                     const double *force, double *weights)
{
    const ln_int K = m->K, L = m->L, n_pairs = m->n_pairs;
    double *inv_m = weights, *accel_weight = inv_m + K, *F_scene = accel_weight + K, *inv_R = F_scene + 3 * K;
    double *pair_weight = inv_R + L;
    ln_int *position = NULL;
    if (m->solver == LN_SOLVER_CHAIN && L > 0) {
        position = malloc((size_t)L * sizeof *position);
        if (!position) return LN_NO_MEMORY;
    }

    /* an anchor's mass is infinite: 1/M = 0, and no force acts on it */
    for (ln_int k = 0; k < K; k++) {
        const int fixed = m->is_fixed[k];
        inv_m[k] = fixed ? 0.0 : 1.0 / mass[k];
        for (int e = 0; e < 3; e++) F_scene[3 * k + e] = fixed ? 0.0 : mass[k] * gravity[e] + force[3 * k + e];
    }
    /* a_k of B (26) is accel_weight[k] times the base force: 1/M_k, and 1 on a driven anchor, whose base-force row
       holds its acceleration */
    for (ln_int k = 0; k < K; k++) accel_weight[k] = inv_m[k];
    for (ln_int j = 0; j < m->n_driven; j++) accel_weight[m->driven_idx[j]] = 1.0;
    for (ln_int l = 0; l < L; l++) inv_R[l] = 1.0 / R[l];
    /* S(l,l')/M of the mass the two links share (21)-(22); 1/M of one end on the diagonal (18) */
    for (ln_int p = 0; p < n_pairs; p++) pair_weight[p] = m->pair_sign[p] * inv_m[m->pair_mass[p]];

    m->R = R;
    m->inv_m = inv_m;
    m->accel_weight = accel_weight;
    m->F_scene = F_scene;
    m->inv_R = inv_R;
    m->pair_weight = pair_weight;
    if (position) {
        /* a chain's tridiagonal A in path order: the diagonal of link i, and the coupling of links i-1 and i in
           row i, summed pair by pair in pair order */
        double *diag = pair_weight + n_pairs, *off = diag + L;
        for (ln_int i = 0; i < L; i++) position[m->chain_order[i]] = i;
        for (ln_int i = 0; i < L; i++) diag[i] = off[i] = 0.0;
        for (ln_int p = 0; p < n_pairs; p++) {
            const ln_int a = position[m->pair_first[p]], b = position[m->pair_second[p]];
            if (a == b) diag[a] += pair_weight[p];
            else off[a > b ? a : b] += pair_weight[p];
        }
        m->chain_diag_weight = diag;
        m->chain_off_weight = off;
        free(position);
    }
    return LN_OK;
}
