/* The diagnostics of a sample of a run: its energy, the worst violations of (11) and (12), its kinetic energy.
 *
 * The definitions are the numpy reference's (linknet_core.dynamics.forces: kinetic_energy, potential_energy;
 * linknet_core.dynamics.equations: constraint_residual, velocity_residual), and so are the orders of their sums,
 * so that a sample's values are the reference's bit for bit: a sum over a sample's entries is numpy's pairwise
 * summation (blocks of up to 128 in 8 accumulators), and a 3-vector dot product sums its products as numpy's
 * einsum does, (x0 y0 + x2 y2) + x1 y1. On the (K,3) state whatever the path (planar scenes included).
 */
#include <math.h>

#include "linknet.h"
#include "ln_math.h"

/* One sample's terms of a sum, by index: what numpy forms as an array and then sums. */
typedef struct sum_terms {
    const ln_model *m;
    const ln_energy_terms *e;
    const double *X, *U;
} sum_terms;

typedef double (*term_fn)(const sum_terms *s, ln_int i);

/* numpy's pairwise summation of term(first), ..., term(first + n - 1) (numpy/_core/src/umath/loops_utils.h:
   pairwise_sum): up to 8 terms in order, up to 128 in 8 interleaved partial sums, beyond that two halves split at
   a multiple of 8. */
static double pairwise_sum(term_fn term, const sum_terms *s, ln_int first, ln_int n)
{
    if (n < 8) {
        double res = 0.0;
        for (ln_int i = 0; i < n; i++) res += term(s, first + i);
        return res;
    }
    if (n <= 128) {
        double r[8];
        ln_int i;
        for (int j = 0; j < 8; j++) r[j] = term(s, first + j);
        for (i = 8; i < n - (n % 8); i += 8)
            for (int j = 0; j < 8; j++) r[j] += term(s, first + i + j);
        double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; i++) res += term(s, first + i);
        return res;
    }
    ln_int half = n / 2;
    half -= half % 8;
    return pairwise_sum(term, s, first, half) + pairwise_sum(term, s, first + half, n - half);
}

/* numpy's sum over a sample: its reduction starts from 0 and adds the pairwise sum */
static double sample_sum(term_fn term, const sum_terms *s, ln_int n)
{
    return 0.0 + pairwise_sum(term, s, 0, n);
}

static double dot3(const double *x, const double *y)
{
    return (x[0] * y[0] + x[2] * y[2]) + x[1] * y[1];
}

/* M_k U_ke^2 over the free masses' coordinates */
static double kinetic_term(const sum_terms *s, ln_int i)
{
    const ln_int k = s->m->free_idx[i / 3];
    const double u = s->U[3 * k + i % 3];
    return s->e->mass[k] * (u * u);
}

/* (M_k g_e) X_ke over every mass (zero weights on anchors) */
static double gravity_term(const sum_terms *s, ln_int i)
{
    return s->e->weight[i] * s->X[i];
}

/* F_ke X_ke over the free masses' coordinates, F the scene's constant forces */
static double force_term(const sum_terms *s, ln_int i)
{
    const ln_int j = 3 * s->m->free_idx[i / 3] + i % 3;
    return s->e->force[j] * s->X[j];
}

/* k (|X_b - X_a| - d0)^2 of spring i */
static double spring_term(const sum_terms *s, ln_int i)
{
    const ln_int a = s->e->spring_mass[2 * i], b = s->e->spring_mass[2 * i + 1];
    const double d[3] = {s->X[3 * b] - s->X[3 * a], s->X[3 * b + 1] - s->X[3 * a + 1], s->X[3 * b + 2] - s->X[3 * a + 2]};
    const double stretch = ln_sqrt(dot3(d, d)) - s->e->spring_param[2 * i + 1];
    return s->e->spring_param[2 * i] * (stretch * stretch);
}

/* the larger, a NaN winning (as numpy's max) */
static double worse(double worst, double v)
{
    return (v > worst || v != v) ? v : worst;
}

void ln_sample_diagnostics(const ln_model *m, const ln_energy_terms *e, const double *X, const double *U,
                           double out[4])
{
    const sum_terms s = {m, e, X, U};
    const double kinetic = 0.5 * sample_sum(kinetic_term, &s, 3 * m->n_free);
    double potential = -sample_sum(gravity_term, &s, 3 * m->K) - sample_sum(force_term, &s, 3 * m->n_free);
    if (e->n_springs) potential = potential + 0.5 * sample_sum(spring_term, &s, e->n_springs);
    double residual = 0.0, velocity_residual = 0.0;
    for (ln_int l = 0; l < m->L; l++) {
        const ln_int a = m->k1[l], b = m->k2[l];
        double d[3], w[3];
        for (int c = 0; c < 3; c++) d[c] = X[3 * b + c] - X[3 * a + c];
        const double rel = fabs(ln_sqrt(dot3(d, d)) / m->R[l] - 1.0);
        for (int c = 0; c < 3; c++) {
            d[c] = d[c] / m->R[l];  /* E_l of (8) */
            w[c] = U[3 * a + c] - U[3 * b + c];
        }
        const double rate = fabs(dot3(d, w));  /* (12): E_l . (U_k1 - U_k2) */
        residual = l ? worse(residual, rel) : rel;
        velocity_residual = l ? worse(velocity_residual, rate) : rate;
    }
    out[0] = kinetic + potential;
    out[1] = residual;
    out[2] = velocity_residual;
    out[3] = kinetic;
}
