/* F_k of (9): everything but the link tensions. The part fixed over an interval (gravity, constant and
   input forces: F_base, zero on anchors) is summed once per advance by data.c; here the state-dependent
   force elements are added to it: viscous drag on the masses that have it, and spring-dampers. */
#include <math.h>

#include "../dim.h"
#include "../linknet.h"
#include "../stages.h"

static inline int has_state_forces(const ln_model *m) { return m->n_drag > 0 || m->n_springs > 0; }

void FN(ln_scene_forces)(const ln_model *m, const double *X, const double *U, const double *F_base, double *F)
{
    const ln_int K = m->K;
    for (ln_int i = 0; i < K * DIM; i++) F[i] = F_base[i];
    for (ln_int i = 0; i < m->n_drag; i++) {
        const ln_int k = m->drag_idx[i];
        const double c = m->drag_coef[i];
        for (int e = 0; e < DIM; e++) F[k * DIM + e] -= c * U[k * DIM + e];
    }
    for (ln_int s = 0; s < m->n_springs; s++) {
        const ln_int a = m->spring_a[s], b = m->spring_b[s];
        double sq = 0.0;
        for (int e = 0; e < DIM; e++) {
            const double dx = X[b * DIM + e] - X[a * DIM + e];
            sq += dx * dx;
        }
        const double dist = sqrt(sq);
        if (dist == 0.0) continue;  /* coincident ends: no direction to pull along */
        const double inv = 1.0 / dist;
        double rate = 0.0;
        for (int e = 0; e < DIM; e++)
            rate += (X[b * DIM + e] - X[a * DIM + e]) * inv * (U[b * DIM + e] - U[a * DIM + e]);
        /* k (d - d0) + c d' along the axis, pulling the ends together when stretched */
        const double f = m->spring_k[s] * (dist - m->spring_rest[s]) + m->spring_c[s] * rate;
        for (int e = 0; e < DIM; e++) {
            const double fn = f * ((X[b * DIM + e] - X[a * DIM + e]) * inv);
            F[a * DIM + e] += fn;
            F[b * DIM + e] -= fn;
        }
    }
    if (m->n_springs > 0)  /* springs may pull on anchors, where no force acts */
        for (ln_int i = 0; i < m->n_fixed; i++)
            for (int e = 0; e < DIM; e++) F[m->fixed_idx[i] * DIM + e] = 0.0;
}
