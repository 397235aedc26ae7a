/* F_k of (9): everything but the link tensions. The part fixed over an interval (gravity, constant and
   input forces: F_base, zero on anchors) is summed once per advance by data.c; here the state-dependent
   force elements are added to it. The kinds are those of the one table linknet_core.scene.description.FORCE_KINDS
   (name, masses, parameters' meaning); a kind's code below is its position there. native/model.py checks the
   names and codes (ln_force_kind_name) against that table when it loads, before any native model is built, so
   a new kind is a row there, a code and a name here and a case in ln_scene_forces, or no such model is built. */
#include <math.h>
#include <string.h>

#include "../dim.h"
#include "../linknet.h"
#include "../ln_math.h"
#include "../stages.h"

#ifndef LINKNET_FORCE_KINDS
#define LINKNET_FORCE_KINDS
enum ln_force_kind_code {
    LN_FORCE_DRAG,      /* one mass k; c: -c U_k (viscous drag) */
    LN_FORCE_SPRING,    /* masses a, b; k, d0, c: k (d - d0) + c d' along the axis, pulling a and b together when
                           stretched (linear spring-damper) */
    LN_FORCE_QUADRATIC_DRAG,    /* one mass k; c: -c |U_k| U_k (aerodynamic drag) */
    LN_FORCE_KIND_COUNT
};
static const char *const force_kind_names[LN_FORCE_KIND_COUNT] = {"drag", "spring", "quadratic_drag"};
#endif

#if DIM == 3
ln_int ln_force_kind(const char *name)
{
    for (int i = 0; i < LN_FORCE_KIND_COUNT; i++)
        if (strcmp(name, force_kind_names[i]) == 0) return i;
    return -1;
}

const char *ln_force_kind_name(ln_int code)
{
    return code >= 0 && code < LN_FORCE_KIND_COUNT ? force_kind_names[code] : NULL;
}
#endif

void FN(ln_scene_forces)(const ln_model *m, const double *X, const double *U, const double *F_base, double *F)
{
    for (ln_int i = 0; i < m->K * DIM; i++) F[i] = F_base[i];
    for (ln_int i = 0; i < m->n_elements; i++) {
        const ln_int a = m->element_mass[2 * i], b = m->element_mass[2 * i + 1];
        const double *p = m->element_param + LN_FORCE_PARAMETERS * i;
        switch (m->element_kind[i]) {
        case LN_FORCE_DRAG:
            for (int e = 0; e < DIM; e++) F[a * DIM + e] -= p[0] * U[a * DIM + e];
            break;
        case LN_FORCE_SPRING: {
            double sq = 0.0;
            for (int e = 0; e < DIM; e++) {
                const double dx = X[b * DIM + e] - X[a * DIM + e];
                sq += dx * dx;
            }
            const double dist = ln_sqrt(sq);
            if (dist == 0.0) break;  /* coincident ends: no direction to pull along */
            const double inv = 1.0 / dist;
            double rate = 0.0;
            for (int e = 0; e < DIM; e++)
                rate += (X[b * DIM + e] - X[a * DIM + e]) * inv * (U[b * DIM + e] - U[a * DIM + e]);
            const double f = p[0] * (dist - p[1]) + p[2] * rate;
            for (int e = 0; e < DIM; e++) {
                const double fn = f * ((X[b * DIM + e] - X[a * DIM + e]) * inv);
                F[a * DIM + e] += fn;
                F[b * DIM + e] -= fn;
            }
            break;
        }
        case LN_FORCE_QUADRATIC_DRAG: {
            double speed = 0.0;
            for (int e = 0; e < DIM; e++) speed += U[a * DIM + e] * U[a * DIM + e];
            const double c = p[0] * ln_sqrt(speed);
            for (int e = 0; e < DIM; e++) F[a * DIM + e] -= c * U[a * DIM + e];
            break;
        }
        default:  /* a code without a case (the model builder refuses unknown kinds): never skipped silently,
                     the forces become NaN and the step fails as non-finite */
            for (int e = 0; e < DIM; e++) F[a * DIM + e] = NAN;
            break;
        }
    }
    if (m->n_elements > 0) {  /* elements may act on anchors (a spring's hook), where no force acts */
        for (ln_int i = 0; i < m->n_fixed; i++)
            for (int e = 0; e < DIM; e++) F[m->fixed_idx[i] * DIM + e] = 0.0;
        for (ln_int i = 0; i < m->n_driven; i++)  /* a driven anchor's row holds its acceleration (drive.c) */
            for (int e = 0; e < DIM; e++) F[m->driven_idx[i] * DIM + e] = F_base[m->driven_idx[i] * DIM + e];
    }
}
